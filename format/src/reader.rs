//! Validating, zero-copy reader.
//!
//! [`MdlodFile::open`] maps the file and checks, before anything is indexed: the header
//! (signature, version range, checksum, stated size), the section table (checksum, every
//! bound with checked arithmetic, alignment, no overlaps, required sections present once),
//! the metadata, the level table and the node records (level, child and point ranges,
//! parent and quantization links, finite values). It reads no particle data. The node
//! records are checked on open for files of at most [`EAGER_NODES`] nodes (with the
//! table's checksum); for larger files only those of the top levels, the rest in blocks
//! of [`NODE_BLOCK`] nodes before they are first read ([`MdlodFile::check_nodes`],
//! [`MdlodFile::check_children`]), so that opening a 10^9-particle file reads a few
//! megabytes. The typed accessors cannot go out of bounds; the records returned by
//! [`MdlodFile::nodes`] are trustworthy where checked. [`MdlodFile::verify`] reads
//! everything: every section checksum, every node record, the (zero) padding between
//! sections, every node's point range, every species index and every decoded point.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use xxhash_rust::xxh3::xxh3_64;

use crate::error::FormatError;
use crate::layout::{
    align_up, Header, LevelRecord, NodeRecord, SectionEntry, SectionKind, HEADER_SIZE, MAGIC,
    READABLE_MAJOR, SECTION_ALIGN,
};
use crate::meta::{AttributeInfo, Metadata, RadiusInfo};
use crate::quantize;

/// Largest metadata section accepted (JSON of a few species needs a few KiB).
const MAX_METADATA_BYTES: u64 = 16 << 20;
/// Largest section table accepted.
const MAX_SECTIONS: u32 = 1 << 16;
/// Deepest hierarchy accepted (levels are stored as u8).
const MAX_LEVELS: usize = 255;

/// Quantized positions of one level.
#[derive(Clone, Copy, Debug)]
pub enum Positions<'a> {
    U8(&'a [[u8; 3]]),
    U16(&'a [[u16; 3]]),
}

impl Positions<'_> {
    pub fn len(&self) -> usize {
        match self {
            Positions::U8(p) => p.len(),
            Positions::U16(p) => p.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The quantized value of point `i`, widened to u16.
    #[inline]
    pub fn get(&self, i: usize) -> [u16; 3] {
        match self {
            Positions::U8(p) => p[i].map(u16::from),
            Positions::U16(p) => p[i],
        }
    }

    /// The raw bytes (3 or 6 per point), e.g. for upload to a GPU.
    pub fn bytes(&self) -> &[u8] {
        match self {
            Positions::U8(p) => bytemuck::cast_slice(p),
            Positions::U16(p) => bytemuck::cast_slice(p),
        }
    }
}

/// An open `.mdlod` file whose structure is validated (its node records as described in
/// the module docs).
pub struct MdlodFile {
    path: PathBuf,
    map: memmap2::Mmap,
    header: Header,
    sections: Vec<SectionEntry>,
    metadata: Metadata,
    levels_range: Range<usize>,
    nodes_range: Range<usize>,
    /// Byte range of POSITIONS per level (empty for level 0).
    positions: Vec<Range<usize>>,
    species_range: Range<usize>,
    attribute_range: Option<Range<usize>>,
    /// The ATTRIBUTES and NODE_ATTRIBUTES sections (the extra attributes), when the
    /// metadata lists any.
    extra_ranges: Option<(Range<usize>, Range<usize>)>,
    /// The node records with another attribute's means in place of the first's
    /// ([`Self::select_attribute`]); `None`: the file's own.
    nodes_owned: Option<Vec<NodeRecord>>,
    /// The attribute hidden value ranges read where it is not the one selected
    /// ([`Self::hide_by_attribute`]): its range and its values' bytes.
    hider: Option<(AttributeInfo, Range<usize>)>,
    /// The file's size and modification time when it was opened ([`Self::changed_on_disk`]).
    opened_as: Option<(std::fs::File, Stamp)>,
    /// The attributes of slots 1 and up of a [`HiddenSet`] ([`Self::hide_by_attributes`]).
    slot_hiders: Vec<Option<(AttributeInfo, Range<usize>)>>,
    radius_range: Option<Range<usize>>,
    /// Per node level: the index in `node_blocks` of its first block.
    block_first: Vec<usize>,
    /// Per block of [`NODE_BLOCK`] nodes of one level: [`BLOCK_VALID`] once its records
    /// passed their checks (every block of the levels checked on open starts so).
    node_blocks: Vec<AtomicU8>,
    /// The first failed check of a block checked after open.
    node_error: OnceLock<(String, String)>,
    /// Every radius a RADIUS_LOG value decodes to, by value (made on first use: a power
    /// per particle is slow where renders decode millions).
    radius_table: OnceLock<Vec<f32>>,
    /// The last [`Self::hidden_below`] computed, with its set.
    species_below: Mutex<Option<(HiddenSet, Arc<[u8]>)>>,
    /// [`MdlodFile::pure_species`], once found.
    pure_species: std::sync::OnceLock<Arc<[u16]>>,
}

/// [`MdlodFile::pure_species`] of a node whose particles are of several species.
pub const MIXED_SPECIES: u16 = u16::MAX;

/// Whether species index `s` is in the set `mask` of [`MdlodFile::species_below`] (bit
/// `s`; indices of 64 and more never are).
pub fn in_species_set(mask: u64, s: usize) -> bool {
    s < 64 && (mask >> s) & 1 == 1
}

/// A file's size and modification time.
type Stamp = (u64, Option<std::time::SystemTime>);

/// The [`Stamp`] of an open file, `None` where it cannot be read.
fn stamp(file: &std::fs::File) -> Option<Stamp> {
    let m = file.metadata().ok()?;
    Some((m.len(), m.modified().ok()))
}

/// The most value ranges a [`HiddenSet`] holds.
pub const MAX_HIDDEN_RANGES: usize = 4;

/// Particles a view leaves out: those of the species of `species` (bit `s` for species
/// index `s`, as [`in_species_set`]) and those whose attribute value, decoded as
/// [`crate::meta::AttributeInfo::decode`] gives it, lies in one of `ranges` (inclusive at
/// both ends; a file without an attribute hides none by value). Each range reads the
/// attribute of its slot: 0 the file's hiding attribute ([`MdlodFile::hiding_attribute`]),
/// `k ≥ 1` the `k`-th [`MdlodFile::hide_by_attributes`] names.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HiddenSet {
    pub species: u64,
    ranges: [[f32; 2]; MAX_HIDDEN_RANGES],
    slots: [u8; MAX_HIDDEN_RANGES],
    count: usize,
}

impl HiddenSet {
    /// The species of `species` only.
    pub fn of_species(species: u64) -> HiddenSet {
        HiddenSet {
            species,
            ..Default::default()
        }
    }

    /// This set and the values in `ranges` (each `[lo, hi]`, `lo ≤ hi`, neither NaN;
    /// an infinite end leaves that side open); `None` past [`MAX_HIDDEN_RANGES`] or
    /// for a range that is not one.
    pub fn with_ranges(self, ranges: &[[f32; 2]]) -> Option<HiddenSet> {
        let slotted: Vec<(u8, [f32; 2])> = ranges.iter().map(|&r| (0, r)).collect();
        self.with_slotted_ranges(&slotted)
    }

    /// This set and the values in `ranges`, each read against the attribute of its slot
    /// (see [`HiddenSet`]); `None` as [`Self::with_ranges`].
    pub fn with_slotted_ranges(self, ranges: &[(u8, [f32; 2])]) -> Option<HiddenSet> {
        if ranges.len() > MAX_HIDDEN_RANGES
            || ranges
                .iter()
                .any(|(_, [lo, hi])| lo.is_nan() || hi.is_nan() || lo > hi)
        {
            return None;
        }
        let mut set = self;
        set.count = ranges.len();
        for (k, &(slot, range)) in ranges.iter().enumerate() {
            set.ranges[k] = range;
            set.slots[k] = slot;
        }
        Some(set)
    }

    /// The value ranges hidden.
    pub fn ranges(&self) -> &[[f32; 2]] {
        &self.ranges[..self.count]
    }

    /// The slot of each of [`Self::ranges`].
    pub fn slots(&self) -> &[u8] {
        &self.slots[..self.count]
    }

    /// Nothing is hidden.
    pub fn is_empty(&self) -> bool {
        self.species == 0 && self.count == 0
    }
}

/// A [`HiddenSet`] as one file's particles are tested against it
/// ([`MdlodFile::hidden_test`]): its value ranges turned once into the quantized values
/// the file stores for them ([`crate::meta::AttributeInfo::codes`]), so a particle's
/// test is a few integer comparisons.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HiddenTest {
    species: u64,
    codes: [(u16, u16); MAX_HIDDEN_RANGES],
    slots: [u8; MAX_HIDDEN_RANGES],
    count: usize,
}

impl HiddenTest {
    /// Whether a particle of species index `s` is hidden, `q` giving its quantized value
    /// of the attribute of a slot (none without one).
    pub fn hides(&self, s: u16, q: impl Fn(u8) -> Option<u16>) -> bool {
        in_species_set(self.species, usize::from(s))
            || self.codes[..self.count]
                .iter()
                .zip(&self.slots)
                .any(|(&(a, b), &slot)| q(slot).is_some_and(|q| a <= q && q <= b))
    }

    /// Some range meets the attribute's values (a particle's value must be read).
    fn by_value(&self) -> bool {
        self.count > 0
    }
}

/// [`MdlodFile::species_below`]: some particle below the node is of a species of the
/// set.
pub const BELOW_IN: u8 = 1;
/// [`MdlodFile::species_below`]: some particle below the node is of a species outside
/// the set.
pub const BELOW_OUT: u8 = 2;

/// Node records are checked in blocks of this many nodes of one level. A view reaches
/// few nodes of each block it touches: a 1 px frame of 2×10^8 particles reads 5.2 M node
/// records and checks 7.1 M with blocks of 256 (11.1 M with 4096, 6.1 M with 64, at the
/// cost of more block flags), about 0.2 s less of its first traversal than with 4096.
pub const NODE_BLOCK: usize = 256;
/// The leading levels holding at most this many nodes together are checked on open;
/// the records of the levels below them, block by block before their first use.
pub const EAGER_NODES: u64 = 1 << 20;
const BLOCK_UNCHECKED: u8 = 0;
const BLOCK_VALID: u8 = 1;
const BLOCK_FAILED: u8 = 2;

/// What [`MdlodFile::verify`] checked.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VerifyReport {
    pub sections: usize,
    pub bytes_hashed: u64,
    pub points_decoded: u64,
    /// Largest distance by which a decoded particle centre lies outside the bounding box
    /// of its parent node (0 for a consistent file, up to float rounding).
    pub max_outside_parent_bounds: f64,
    /// Largest distance by which a decoded particle centre lies beyond its parent's
    /// bounds shrunk by its radius (where its true centre lies): a lower bound of the
    /// file's position error, at most the recorded one up to rounding.
    pub max_particle_error_seen: f64,
}

impl MdlodFile {
    /// Opens and validates `path`.
    ///
    /// The node records of the top levels (up to [`EAGER_NODES`] nodes) are checked
    /// here; those of larger levels block by block before first use
    /// ([`Self::check_nodes`]); [`Self::verify`] checks everything.
    pub fn open(path: impl AsRef<Path>) -> Result<MdlodFile, FormatError> {
        Self::open_with_eager_nodes(path, EAGER_NODES)
    }

    /// [`Self::open`] checking the records of the leading levels of at most
    /// `eager_nodes` nodes together (all of them when the file has no more) on open.
    pub fn open_with_eager_nodes(
        path: impl AsRef<Path>,
        eager_nodes: u64,
    ) -> Result<MdlodFile, FormatError> {
        let path = path.as_ref().to_path_buf();
        let file = crate::files::open(&path).map_err(|e| FormatError::io(&path, e))?;
        let stamp = stamp(&file);
        let map = crate::mmap::map_file(&file).map_err(|e| FormatError::io(&path, e))?;
        let mut f = Self::from_map(path, map, eager_nodes)?;
        f.opened_as = stamp.map(|s| (file, s));
        Ok(f)
    }

    /// [`Self::open`] for reading its header, metadata and tables only (a batch telling
    /// whether a frame file is complete and how it was made; a merge comparing
    /// settings): the top level's records are checked on open, the others before their
    /// first use, and the file is mapped without the kernel's read-ahead, so that opening
    /// a file of gigabytes reads a few pages of it rather than megabytes around each
    /// (a cluster file system may read ahead tens of megabytes). [`Self::verify`] still
    /// checks everything.
    pub fn open_sparse(path: impl AsRef<Path>) -> Result<MdlodFile, FormatError> {
        let path = path.as_ref().to_path_buf();
        let file = crate::files::open(&path).map_err(|e| FormatError::io(&path, e))?;
        let stamp = stamp(&file);
        let map = crate::mmap::map_file(&file).map_err(|e| FormatError::io(&path, e))?;
        // (Advice only: a kernel that refuses it reads as it would.)
        let _ = map.advise(crate::mmap::Advice::Random);
        let mut f = Self::from_map(path, map, 1)?;
        f.opened_as = stamp.map(|s| (file, s));
        Ok(f)
    }

    /// Whether the file opened (its inode, whatever its name now names) has another size
    /// or modification time than when it was opened: rewritten in place while it was read
    /// (`cp` over it), part of what was read came from its new bytes, which callers say
    /// rather than present the result as the file's. A file replaced by rename is not
    /// changed: the old one stays mapped whole.
    pub fn changed_on_disk(&self) -> bool {
        self.opened_as
            .as_ref()
            .is_some_and(|(file, was)| stamp(file).as_ref() != Some(was))
    }

    fn from_map(
        path: PathBuf,
        map: memmap2::Mmap,
        eager_nodes: u64,
    ) -> Result<MdlodFile, FormatError> {
        let len = map.len() as u64;
        let corrupt = |place: &str, problem: String| FormatError::corrupt(&path, place, problem);

        // Header.
        if map.get(..8) == Some(&crate::sndf::SNDF_MAGIC[..]) {
            return Err(FormatError::SndfNotMdlod { path });
        }
        if map.len() < HEADER_SIZE {
            if map.len() >= 8 && map[..8] != MAGIC {
                return Err(FormatError::BadMagic { path });
            }
            return Err(corrupt(
                "header",
                format!("file is {len} bytes, shorter than the {HEADER_SIZE}-byte header"),
            ));
        }
        let header: Header = bytemuck::pod_read_unaligned(&map[..HEADER_SIZE]);
        if header.magic != MAGIC {
            return Err(FormatError::BadMagic { path });
        }
        if !READABLE_MAJOR.contains(&header.version_major) {
            let newer = header.version_major > *READABLE_MAJOR.end();
            return Err(FormatError::UnsupportedVersion {
                path,
                major: header.version_major,
                minor: header.version_minor,
                readable_min: *READABLE_MAJOR.start(),
                readable_max: *READABLE_MAJOR.end(),
                hint: if newer {
                    "it was written by a newer mdlod: upgrade mdlod to read it"
                } else {
                    "convert the source data again with this mdlod"
                },
            });
        }
        let computed = xxh3_64(&map[..56]);
        if computed != header.header_checksum {
            return Err(FormatError::Checksum {
                path,
                place: "header (bytes 0..56)".into(),
                stored: header.header_checksum,
                computed,
            });
        }
        if header.file_size != len {
            return Err(corrupt(
                "header",
                format!(
                    "states a file size of {} bytes but the file has {len} (truncated or appended to)",
                    header.file_size
                ),
            ));
        }
        if header.position_bits != 8 && header.position_bits != 16 {
            return Err(corrupt(
                "header (offset 20)",
                format!("position bits {} (must be 8 or 16)", header.position_bits),
            ));
        }

        // Section table.
        if header.section_count > MAX_SECTIONS {
            return Err(corrupt(
                "header (offset 16)",
                format!("{} sections (at most {MAX_SECTIONS})", header.section_count),
            ));
        }
        let table_len = u64::from(header.section_count) * 32;
        let table_end = header
            .section_table_offset
            .checked_add(table_len)
            .filter(|&end| {
                end <= len
                    && header.section_table_offset >= HEADER_SIZE as u64
                    && align_up(header.section_table_offset) == Some(header.section_table_offset)
            });
        let Some(table_end) = table_end else {
            return Err(corrupt(
                "header (offset 24)",
                format!(
                    "section table at {} with {} entries does not lie inside the {len}-byte file, or its offset is not a multiple of {SECTION_ALIGN}",
                    header.section_table_offset, header.section_count
                ),
            ));
        };
        let table_bytes = &map[header.section_table_offset as usize..table_end as usize];
        let computed = xxh3_64(table_bytes);
        if computed != header.section_table_checksum {
            return Err(FormatError::Checksum {
                path,
                place: format!("section table at offset {}", header.section_table_offset),
                stored: header.section_table_checksum,
                computed,
            });
        }
        let sections: Vec<SectionEntry> = table_bytes
            .chunks_exact(32)
            .map(bytemuck::pod_read_unaligned)
            .collect();

        let place_of = |i: usize, s: &SectionEntry| {
            let name = SectionKind::from_code(s.kind).map_or("unknown", SectionKind::name);
            format!(
                "section {i} ({name}, level {}) at offset {}",
                s.level, s.offset
            )
        };
        let mut spans: Vec<(u64, u64, usize)> = Vec::with_capacity(sections.len());
        for (i, s) in sections.iter().enumerate() {
            let end = s
                .offset
                .checked_add(s.length)
                .filter(|&e| e <= header.section_table_offset);
            if s.offset % SECTION_ALIGN != 0 || s.offset < HEADER_SIZE as u64 || end.is_none() {
                return Err(corrupt(
                    &place_of(i, s),
                    format!(
                        "length {} does not fit between the header and the section table at {}, or the offset is not a multiple of {SECTION_ALIGN}",
                        s.length, header.section_table_offset
                    ),
                ));
            }
            spans.push((s.offset, s.offset + s.length, i));
        }
        spans.sort_unstable();
        for w in spans.windows(2) {
            if w[1].0 < w[0].1 {
                return Err(corrupt(
                    &place_of(w[1].2, &sections[w[1].2]),
                    format!("overlaps section {}", w[0].2),
                ));
            }
        }

        let find = |kind: SectionKind, level: Option<u32>| -> Result<Option<usize>, FormatError> {
            let mut found = None;
            for (i, s) in sections.iter().enumerate() {
                if s.kind == kind as u32 && level.is_none_or(|l| s.level == l) {
                    if found.is_some() {
                        return Err(FormatError::corrupt(
                            &path,
                            place_of(i, s),
                            format!("second {} section", kind.name()),
                        ));
                    }
                    found = Some(i);
                }
            }
            Ok(found)
        };
        let require = |kind: SectionKind, level: Option<u32>| -> Result<usize, FormatError> {
            find(kind, level)?.ok_or_else(|| {
                FormatError::corrupt(
                    &path,
                    "section table",
                    match level {
                        Some(l) => format!("no {} section for level {l}", kind.name()),
                        None => format!("no {} section", kind.name()),
                    },
                )
            })
        };
        let range = |i: usize| {
            let s = &sections[i];
            s.offset as usize..(s.offset + s.length) as usize
        };
        let check_sum = |i: usize| -> Result<(), FormatError> {
            let computed = xxh3_64(&map[range(i)]);
            if computed != sections[i].checksum {
                return Err(FormatError::Checksum {
                    path: path.clone(),
                    place: place_of(i, &sections[i]),
                    stored: sections[i].checksum,
                    computed,
                });
            }
            Ok(())
        };

        // Metadata.
        let mi = require(SectionKind::Metadata, None)?;
        if sections[mi].length > MAX_METADATA_BYTES {
            return Err(corrupt(
                &place_of(mi, &sections[mi]),
                format!(
                    "{} bytes of metadata (at most {MAX_METADATA_BYTES})",
                    sections[mi].length
                ),
            ));
        }
        check_sum(mi)?;
        if let Err(e) = std::str::from_utf8(&map[range(mi)]) {
            return Err(corrupt(
                "METADATA",
                format!("not UTF-8 text (byte {} of the section)", e.valid_up_to()),
            ));
        }
        // One object (FORMAT.md §7): serde would also take an array of its fields in
        // their order.
        if map[range(mi)].iter().find(|b| !b.is_ascii_whitespace()) == Some(&b'[') {
            return Err(corrupt(
                "METADATA",
                "a JSON array where the format has one JSON object".into(),
            ));
        }
        let mut metadata: Metadata =
            serde_json::from_slice(&map[range(mi)]).map_err(|source| FormatError::Metadata {
                path: path.clone(),
                source,
            })?;
        // A reader may rely on the bound (section 6): one that is none is refused here,
        // not only by `verify`.
        let error = metadata.max_position_error;
        if !(error.is_finite() && error >= 0.0) {
            return Err(corrupt(
                "METADATA",
                format!("maximum position error {error} is not a finite non-negative number"),
            ));
        }
        // Radii on a log scale (`radius_log`) are the metadata's `radius`, marked so.
        if let Some(r) = metadata.radius_log.take() {
            if metadata.radius.is_some() {
                return Err(corrupt(
                    "METADATA",
                    "gives both `radius` and `radius_log` (the radii are quantized one way)".into(),
                ));
            }
            metadata.radius = Some(RadiusInfo { log: true, ..r });
        }
        // The objects of section 7 are objects: serde would also take a list of their
        // values in order (`"radius": [0.3, 0.9]`), which the spec does not allow.
        if let Some(problem) = Self::not_an_object(&map[range(mi)]) {
            return Err(corrupt("METADATA", problem));
        }
        if let Some(bytes) = metadata.source.as_ref().and_then(|s| s.bytes.as_ref()) {
            if !bytes.checksum_well_formed() {
                return Err(corrupt(
                    "METADATA",
                    format!(
                        "source.bytes.xxh3 {:?} is not 16 lowercase hexadecimal digits",
                        bytes.xxh3.chars().take(40).collect::<String>()
                    ),
                ));
            }
        }

        // Levels.
        let li = require(SectionKind::Levels, None)?;
        check_sum(li)?;
        let level_bytes = &map[range(li)];
        // (Not `is_multiple_of`: the workspace's minimum Rust is 1.85.)
        if !level_bytes.chunks_exact(32).remainder().is_empty() {
            return Err(corrupt(
                &place_of(li, &sections[li]),
                "length is not a multiple of 32".into(),
            ));
        }
        let levels: &[LevelRecord] = bytemuck::try_cast_slice(level_bytes)
            .map_err(|e| corrupt(&place_of(li, &sections[li]), format!("misaligned: {e}")))?;
        let level_count = levels.len();
        if !(2..=MAX_LEVELS).contains(&level_count) {
            return Err(corrupt(
                &place_of(li, &sections[li]),
                format!("{level_count} levels (must be 2 to {MAX_LEVELS})"),
            ));
        }
        let last = level_count - 1;
        if levels[0].point_count != 1 {
            return Err(corrupt(
                "level 0",
                format!(
                    "{} points (must be the single top node)",
                    levels[0].point_count
                ),
            ));
        }
        let mut node_total: u64 = 0;
        for (l, lv) in levels.iter().enumerate() {
            if lv.point_count == 0 || lv.point_count > u64::from(u32::MAX) {
                return Err(corrupt(
                    &format!("level {l}"),
                    format!("{} points (must be 1 to 2^32-1)", lv.point_count),
                ));
            }
            if lv.node_first != node_total {
                return Err(corrupt(
                    &format!("level {l}"),
                    format!("first node {} (expected {node_total})", lv.node_first),
                ));
            }
            if l < last {
                node_total += lv.point_count;
            }
        }
        // Node indices are u32 (parent, quant_node), 0xFFFFFFFF meaning none.
        if node_total > u64::from(u32::MAX) {
            return Err(corrupt(
                &format!("level {last}"),
                format!(
                    "{node_total} nodes above it (at most 2^32-1: nodes are numbered in 32 bits)"
                ),
            ));
        }
        if metadata.particles != levels[last].point_count {
            return Err(corrupt(
                "METADATA",
                format!(
                    "says {} particles but the finest level holds {}",
                    metadata.particles, levels[last].point_count
                ),
            ));
        }
        let delta_n = metadata.build.delta_n as usize;
        if delta_n == 0 || delta_n > last {
            return Err(corrupt(
                "METADATA",
                format!("build.delta_n {delta_n} (must be 1 to {last})"),
            ));
        }
        if metadata.build.position_bits != header.position_bits {
            return Err(corrupt(
                "METADATA",
                format!(
                    "build.position_bits {} disagrees with the header's {}",
                    metadata.build.position_bits, header.position_bits
                ),
            ));
        }
        if metadata.species.is_empty() || metadata.species.len() > usize::from(u16::MAX) {
            return Err(corrupt(
                "METADATA",
                format!("{} species (must be 1 to 65535)", metadata.species.len()),
            ));
        }
        if let Some(s) = metadata
            .species
            .iter()
            .find(|s| !(s.radius.is_finite() && s.radius > 0.0))
        {
            return Err(corrupt(
                "METADATA",
                format!(
                    "species {:?}: radius {} (must be a finite number above 0)",
                    s.name, s.radius
                ),
            ));
        }
        if let Some(s) = metadata
            .species
            .iter()
            .find(|s| !s.colour.iter().all(|c| (0.0..=1.0).contains(c)))
        {
            return Err(corrupt(
                "METADATA",
                format!(
                    "species {:?}: colour {:?} (must be three numbers from 0 to 1)",
                    s.name, s.colour
                ),
            ));
        }
        if let Some(a) = metadata
            .attribute
            .as_ref()
            .filter(|a| !(a.min.is_finite() && a.max.is_finite() && a.min <= a.max))
        {
            return Err(corrupt(
                "METADATA",
                format!(
                    "attribute {:?}: range {} to {} (must be two finite numbers, the smaller \
                     first)",
                    a.name, a.min, a.max
                ),
            ));
        }
        // The first attribute's logarithm is said by `attribute_log10` alone.
        if let Some(a) = metadata.attribute.as_ref().filter(|a| a.log10) {
            return Err(corrupt(
                "METADATA",
                format!(
                    "attribute {:?}: `log10` is set in `attribute` (the first attribute's \
                     logarithm is said by `attribute_log10`; `log10` belongs to the entries \
                     of `attributes`)",
                    a.name
                ),
            ));
        }
        // Extra attributes: at most the format's number (counted before anything is
        // compared), valid ranges, distinct names (the first's too), and only with a
        // first attribute.
        if metadata.attributes.len() > crate::layout::MAX_EXTRA_ATTRIBUTES {
            return Err(corrupt(
                "METADATA",
                format!(
                    "{} extra attributes (at most {})",
                    metadata.attributes.len(),
                    crate::layout::MAX_EXTRA_ATTRIBUTES
                ),
            ));
        }
        for (k, a) in metadata.attributes.iter().enumerate() {
            let problem = if !(a.min.is_finite() && a.max.is_finite() && a.min <= a.max) {
                Some(format!(
                    "range {} to {} (must be two finite numbers, the smaller first)",
                    a.min, a.max
                ))
            } else if metadata.attribute.as_ref().is_none_or(|p| p.name == a.name)
                || metadata.attributes[..k].iter().any(|b| b.name == a.name)
            {
                Some(match &metadata.attribute {
                    None => "an extra attribute without a first (`attribute`)".to_string(),
                    Some(_) => "a name given twice".to_string(),
                })
            } else {
                None
            };
            if let Some(problem) = problem {
                return Err(corrupt(
                    "METADATA",
                    format!("attributes[{k}] {:?}: {problem}", a.name),
                ));
            }
        }
        if let Some(r) = metadata.radius.as_ref().filter(|r| !r.is_valid()) {
            return Err(corrupt(
                "METADATA",
                if r.log {
                    format!(
                        "radius_log range {} to {} (must be two finite numbers above 0, the \
                         smaller first)",
                        r.min, r.max
                    )
                } else {
                    format!(
                        "radius range {} to {} (must be two finite numbers from 0 up, the \
                         smaller first)",
                        r.min, r.max
                    )
                },
            ));
        }
        if let Some(s) = metadata.species.iter().find(|s| {
            s.radius_range
                .is_some_and(|[lo, hi]| !(lo.is_finite() && hi.is_finite() && 0.0 < lo && lo <= hi))
        }) {
            return Err(corrupt(
                "METADATA",
                format!(
                    "species {:?}: radius_range {:?} (must be two positive numbers, the \
                     smaller first)",
                    s.name,
                    s.radius_range.unwrap_or_default()
                ),
            ));
        }

        // Nodes.
        let ni = require(SectionKind::Nodes, None)?;
        if sections[ni].length != node_total * 96 {
            return Err(corrupt(
                &place_of(ni, &sections[ni]),
                format!(
                    "{} bytes, expected {node_total} nodes of 96 bytes",
                    sections[ni].length
                ),
            ));
        }
        // The leading levels of at most EAGER_NODES nodes together are checked now (all
        // of a file that small, with the table's checksum); the records of larger levels
        // are checked block by block before they are first used (`check_nodes`), so that
        // opening a large file reads neither its whole node table nor, for the first
        // coarse image, more than its top.
        // The top node is always checked: every walk starts there.
        let mut eager_levels = 1;
        let mut eager_total = 1u64;
        while eager_levels < last {
            eager_total += levels[eager_levels].point_count;
            if eager_total > eager_nodes && node_total > eager_nodes {
                break;
            }
            eager_levels += 1;
        }
        let all_eager = eager_levels == last;
        // The checksum runs beside the node checks (both read the whole table, when the
        // file is small enough to be checked whole); its
        // error, then a misaligned table's, comes first, as if run one after another.
        let (sum, nodes) = std::thread::scope(|scope| {
            let sum = scope.spawn(|| if all_eager { check_sum(ni) } else { Ok(()) });
            let nodes = bytemuck::try_cast_slice::<u8, NodeRecord>(&map[range(ni)])
                .map_err(|e| corrupt(&place_of(ni, &sections[ni]), format!("misaligned: {e}")))
                .and_then(|nodes| {
                    validate_nodes(
                        &path,
                        nodes,
                        levels,
                        NodeRules {
                            delta_n,
                            species_count: metadata.species.len(),
                            half_range: crate::quantize::half_range(header.position_bits),
                        },
                        eager_levels,
                    )
                    .map(|()| nodes)
                });
            let sum = sum.join().unwrap_or_else(|e| std::panic::resume_unwind(e));
            (sum, nodes)
        });
        sum?;
        nodes?;
        let mut block_first = Vec::with_capacity(last);
        let mut node_blocks = Vec::new();
        for (l, lv) in levels[..last].iter().enumerate() {
            block_first.push(node_blocks.len());
            let state = if l < eager_levels {
                BLOCK_VALID
            } else {
                BLOCK_UNCHECKED
            };
            let blocks = (lv.point_count as usize).div_ceil(NODE_BLOCK);
            node_blocks.extend((0..blocks).map(|_| AtomicU8::new(state)));
        }

        // Per-point sections.
        let bytes_per_point = 3 * (header.position_bits as u64 / 8);
        let mut positions = Vec::with_capacity(level_count);
        positions.push(0..0);
        for (l, lv) in levels.iter().enumerate().skip(1) {
            let i = require(SectionKind::Positions, Some(l as u32))?;
            if sections[i].length != lv.point_count * bytes_per_point {
                return Err(corrupt(
                    &place_of(i, &sections[i]),
                    format!(
                        "{} bytes, expected {} points of {bytes_per_point} bytes",
                        sections[i].length, lv.point_count
                    ),
                ));
            }
            positions.push(range(i));
        }
        let n = levels[last].point_count;
        let si = require(SectionKind::Species, Some(last as u32))?;
        if sections[si].length != n * 2 {
            return Err(corrupt(
                &place_of(si, &sections[si]),
                format!(
                    "{} bytes, expected {n} u16 species indices",
                    sections[si].length
                ),
            ));
        }
        // An optional per-particle section of `n` u16 `values`: present exactly when the
        // metadata gives its `field` (`described`: how, for the message).
        let optional = |kind: SectionKind, described: Option<String>, field: &str, values: &str| {
            let name = kind.name();
            let a = if name.starts_with(['A', 'E', 'I', 'O', 'U']) {
                "an"
            } else {
                "a"
            };
            match (find(kind, Some(last as u32))?, described) {
                (Some(i), Some(_)) => {
                    if sections[i].length != n * 2 {
                        return Err(corrupt(
                            &place_of(i, &sections[i]),
                            format!("{} bytes, expected {n} u16 {values}", sections[i].length),
                        ));
                    }
                    Ok(Some(range(i)))
                }
                (None, None) => Ok(None),
                (Some(_), None) => Err(corrupt(
                    "METADATA",
                    format!("{a} {name} section is present but the metadata gives no {field}"),
                )),
                (None, Some(what)) => Err(corrupt(
                    "section table",
                    format!("the metadata gives {what} but there is no {name} section"),
                )),
            }
        };
        let attribute_range = optional(
            SectionKind::Attribute,
            metadata
                .attribute
                .as_ref()
                .map(|a| format!("attribute {:?}", a.name)),
            "attribute",
            "values",
        )?;
        // Radii linear (RADIUS, `radius`) or on a log scale (RADIUS_LOG, `radius_log`):
        // the section of the other scale is refused as the metadata not giving it.
        let log = metadata.radius.is_some_and(|r| r.log);
        let (given, other) = if log {
            (SectionKind::RadiusLog, SectionKind::Radius)
        } else {
            (SectionKind::Radius, SectionKind::RadiusLog)
        };
        let radius_range = optional(
            given,
            metadata.radius.map(|_| {
                if log {
                    "a radius_log range".to_string()
                } else {
                    "a radius range".to_string()
                }
            }),
            if log {
                "radius_log range"
            } else {
                "radius range"
            },
            "radii",
        )?;
        optional(
            other,
            None,
            if log {
                "radius range"
            } else {
                "radius_log range"
            },
            "radii",
        )?;

        // The extra attributes: a u16 per particle and an f32 per node for each.
        let extras = metadata.attributes.len() as u64;
        let node_count = sections[ni].length / std::mem::size_of::<NodeRecord>() as u64;
        let extra_ranges = {
            let mut found = Vec::new();
            for (kind, level, per) in [
                (SectionKind::Attributes, last as u32, n * 2),
                (SectionKind::NodeAttributes, 0, node_count * 4),
            ] {
                let name = kind.name();
                match (find(kind, Some(level))?, extras) {
                    (Some(i), 0) => {
                        return Err(corrupt(
                            "METADATA",
                            format!(
                                "{} ({}) is present but the metadata lists no `attributes`",
                                name,
                                place_of(i, &sections[i])
                            ),
                        ))
                    }
                    (None, 0) => {}
                    (None, _) => {
                        return Err(corrupt(
                            "section table",
                            format!(
                                "the metadata lists {extras} `attributes` but there is no {name} \
                                 section"
                            ),
                        ))
                    }
                    (Some(i), k) => {
                        if Some(sections[i].length) != per.checked_mul(k) {
                            return Err(corrupt(
                                &place_of(i, &sections[i]),
                                format!(
                                    "{} bytes, expected {k} attributes of {per} bytes",
                                    sections[i].length
                                ),
                            ));
                        }
                        found.push(range(i));
                    }
                }
            }
            match <[Range<usize>; 2]>::try_from(found) {
                Ok([a, b]) => Some((a, b)),
                Err(_) => None,
            }
        };

        let levels_range = range(li);
        let nodes_range = range(ni);
        let species_range = range(si);
        Ok(MdlodFile {
            path,
            map,
            header,
            sections,
            metadata,
            levels_range,
            nodes_range,
            positions,
            species_range,
            attribute_range,
            extra_ranges,
            nodes_owned: None,
            hider: None,
            opened_as: None,
            slot_hiders: Vec::new(),
            radius_table: OnceLock::new(),
            radius_range,
            block_first,
            node_blocks,
            node_error: OnceLock::new(),
            species_below: Mutex::new(None),
            pure_species: std::sync::OnceLock::new(),
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn header(&self) -> &Header {
        &self.header
    }

    pub fn sections(&self) -> &[SectionEntry] {
        &self.sections
    }

    pub fn metadata(&self) -> &Metadata {
        &self.metadata
    }

    #[inline]
    pub fn position_bits(&self) -> u32 {
        self.header.position_bits
    }

    #[inline]
    pub fn delta_n(&self) -> usize {
        self.metadata.build.delta_n as usize
    }

    #[inline]
    pub fn levels(&self) -> &[LevelRecord] {
        bytemuck::cast_slice(&self.map[self.levels_range.clone()])
    }

    #[inline]
    pub fn level_count(&self) -> usize {
        self.levels().len()
    }

    pub fn particle_count(&self) -> u64 {
        self.metadata.particles
    }

    /// All nodes, level by level; node `levels()[l].node_first + i` is point `i` of level `l`.
    ///
    /// The records of the levels checked on open ([`EAGER_NODES`]) are valid; the others
    /// only once [`Self::check_nodes`] (or [`Self::check_children`] of their parent)
    /// has passed for them: until then they are bytes of the file, which may be corrupt.
    /// (Every access stays in bounds whatever they hold; only their values may be wrong.)
    #[inline]
    pub fn nodes(&self) -> &[NodeRecord] {
        match &self.nodes_owned {
            Some(nodes) => nodes,
            None => bytemuck::cast_slice(&self.map[self.nodes_range.clone()]),
        }
    }

    /// The names of the attributes the file keeps: the first (`attribute`), then the
    /// extra ones (`attributes`); empty without any.
    pub fn attribute_names(&self) -> Vec<&str> {
        let m = &self.metadata;
        m.attribute
            .iter()
            .chain(&m.attributes)
            .map(|a| a.name.as_str())
            .collect()
    }

    /// The means of extra attribute `k` per node (the NODE_ATTRIBUTES section's `k`-th
    /// part), when the file has it.
    pub fn extra_node_means(&self, k: usize) -> Option<&[f32]> {
        let (_, nodes) = self.extra_ranges.as_ref()?;
        let all: &[f32] = bytemuck::cast_slice(&self.map[nodes.clone()]);
        let n = all.len() / self.metadata.attributes.len().max(1);
        all.get(k * n..(k + 1) * n)
    }

    /// The quantized values of extra attribute `k` per particle (the ATTRIBUTES
    /// section's `k`-th part), when the file has it.
    pub fn extra_values(&self, k: usize) -> Option<&[u16]> {
        let (values, _) = self.extra_ranges.as_ref()?;
        let all: &[u16] = bytemuck::cast_slice(&self.map[values.clone()]);
        let n = all.len() / self.metadata.attributes.len().max(1);
        all.get(k * n..(k + 1) * n)
    }

    /// This file with the attribute named `name` in the first's place: its values,
    /// range and node means are those every reader of the first attribute (colours,
    /// splat light, hidden values) takes, and it is the file's only attribute (select
    /// another from a fresh open). The first attribute's name gives the file as it is.
    /// The node records are copied (a file with extra attributes was built whole, at most
    /// a chunk's particles); a mean that is not finite is refused, naming the node. An
    /// unknown name is an error listing the file's attributes.
    pub fn select_attribute(mut self, name: &str) -> Result<MdlodFile, FormatError> {
        let chosen = attribute_named(&self.attribute_names(), name)
            .unwrap_or(name)
            .to_string();
        let name = chosen.as_str();
        if self
            .metadata
            .attribute
            .as_ref()
            .is_some_and(|a| a.name == name)
        {
            return Ok(self);
        }
        let Some(k) = self.metadata.attributes.iter().position(|a| a.name == name) else {
            return Err(self.no_such_attribute(name));
        };
        let values = self.extra_values_range(k)?;
        let means = self.extra_node_means(k).unwrap_or_default();
        let mut nodes = self.nodes().to_vec();
        if means.len() != nodes.len() {
            return Err(FormatError::corrupt(
                &self.path,
                "NODE_ATTRIBUTES",
                format!("{} means for {} nodes", means.len(), nodes.len()),
            ));
        }
        for (i, (n, &m)) in nodes.iter_mut().zip(means).enumerate() {
            if !m.is_finite() {
                return Err(FormatError::corrupt(
                    &self.path,
                    format!("NODE_ATTRIBUTES, attribute {name:?}, node {i}"),
                    format!("mean {m} is not finite"),
                ));
            }
            n.attribute = m;
        }
        self.nodes_owned = Some(nodes);
        self.attribute_range = Some(values);
        // The file is then one of that attribute alone (its metadata, its values and
        // means; no further attributes): another is selected from a fresh open.
        // (An entry's `log10` becomes the first's `attribute_log10`.)
        let mut chosen = self.metadata.attributes[k].clone();
        self.metadata.attribute_log10 = std::mem::take(&mut chosen.log10);
        self.metadata.attribute = Some(chosen);
        self.metadata.attributes.clear();
        self.extra_ranges = None;
        // Hidden values depend on the attribute: a set computed before is stale.
        *self.species_below.lock().unwrap_or_else(|e| e.into_inner()) = None;
        Ok(self)
    }

    /// The error for an attribute name the file does not keep, listing those it does.
    fn no_such_attribute(&self, name: &str) -> FormatError {
        let names = self.attribute_names();
        // A name that differs in case only (`C_CNA`): the one meant, said first.
        let near = names.iter().find(|n| n.eq_ignore_ascii_case(name));
        FormatError::NoSuchAttribute {
            path: self.path.clone(),
            name: name.to_string(),
            names: match (names.is_empty(), near) {
                (true, _) => "none".to_string(),
                (false, Some(n)) => {
                    format!(
                        "{}; a name differs only in case: did you mean {n}?",
                        names.join(", ")
                    )
                }
                (false, None) => names.join(", "),
            },
        }
    }

    /// The bytes of extra attribute `k`'s values (the ATTRIBUTES section's `k`-th part).
    fn extra_values_range(&self, k: usize) -> Result<Range<usize>, FormatError> {
        let (values, _) = self
            .extra_ranges
            .clone()
            .ok_or_else(|| FormatError::corrupt(&self.path, "section table", "no ATTRIBUTES"))?;
        let per = (values.end - values.start) / self.metadata.attributes.len().max(1);
        Ok(values.start + k * per..values.start + (k + 1) * per)
    }

    /// This file with hidden value ranges ([`HiddenSet::with_ranges`]) read against the
    /// attribute named `name` (as [`Self::select_attribute`] names them) instead of the
    /// selected one: an OVITO user's selection by one column (a CNA's structure types)
    /// while colouring by another. Kept through a later [`Self::select_attribute`]. An
    /// unknown name is an error listing the file's attributes.
    pub fn hide_by_attribute(mut self, name: &str) -> Result<MdlodFile, FormatError> {
        self.hider = self.attribute_values_named(name)?;
        *self.species_below.lock().unwrap_or_else(|e| e.into_inner()) = None;
        Ok(self)
    }

    /// This file with the attributes of a [`HiddenSet`]'s slots 1 and up: `names[k − 1]`
    /// for slot `k` (as [`Self::select_attribute`] names them), so that one view hides by
    /// several columns at once (a CNA's fcc atoms and the low energies). Kept through a
    /// later [`Self::select_attribute`]. An unknown name is an error listing the file's
    /// attributes.
    pub fn hide_by_attributes(mut self, names: &[&str]) -> Result<MdlodFile, FormatError> {
        // (Each name keeps its slot, one the file cannot read included.)
        let mut hiders = Vec::with_capacity(names.len());
        for name in names {
            hiders.push(self.attribute_values_named(name)?);
        }
        self.slot_hiders = hiders;
        *self.species_below.lock().unwrap_or_else(|e| e.into_inner()) = None;
        Ok(self)
    }

    /// The attribute named `name` and the bytes of its values, as the file holds them now.
    fn attribute_values_named(
        &self,
        name: &str,
    ) -> Result<Option<(AttributeInfo, Range<usize>)>, FormatError> {
        let names = self.attribute_names();
        let Some(chosen) = attribute_named(&names, name).map(str::to_owned) else {
            return Err(self.no_such_attribute(name));
        };
        let first = self.metadata.attribute.as_ref();
        if first.is_some_and(|a| a.name == chosen) {
            return Ok(first.cloned().zip(self.attribute_range.clone()));
        }
        let Some(k) = self
            .metadata
            .attributes
            .iter()
            .position(|a| a.name == chosen)
        else {
            return Ok(None);
        };
        Ok(Some((
            self.metadata.attributes[k].clone(),
            self.extra_values_range(k)?,
        )))
    }

    /// The attribute a [`HiddenSet`]'s slot reads (slot 0: [`Self::hiding_attribute`]).
    pub fn hidden_slot_attribute(&self, slot: u8) -> Option<&AttributeInfo> {
        self.slot_attribute(slot).map(|(info, _)| info)
    }

    /// Whether some particle's stored value of the attribute of a [`HiddenSet`]'s slot
    /// lies in `codes` (quantized values, inclusive; see
    /// [`crate::meta::AttributeInfo::codes`]): a scan of that attribute's section, which
    /// stops at the first. `false` for a slot without an attribute.
    pub fn slot_values_meet(&self, slot: u8, codes: (u16, u16)) -> bool {
        let (lo, hi) = codes;
        self.slot_attribute(slot)
            .and_then(|(_, v)| v)
            .is_some_and(|v| v.iter().any(|&q| lo <= q && q <= hi))
    }

    /// The attribute of a [`HiddenSet`]'s slot and its quantized values per particle.
    fn slot_attribute(&self, slot: u8) -> Option<(&AttributeInfo, Option<&[u16]>)> {
        match slot {
            0 => Some((self.hiding_attribute()?, self.hiding_values())),
            k => {
                let (info, r) = self.slot_hiders.get(usize::from(k) - 1)?.as_ref()?;
                Some((info, Some(bytemuck::cast_slice(&self.map[r.clone()]))))
            }
        }
    }

    /// The attribute hidden value ranges are read against: the one
    /// [`Self::hide_by_attribute`] chose, else the selected (first) one.
    pub fn hiding_attribute(&self) -> Option<&AttributeInfo> {
        match &self.hider {
            Some((info, _)) => Some(info),
            None => self.metadata.attribute.as_ref(),
        }
    }

    /// The quantized values of [`Self::hiding_attribute`] per particle.
    pub fn hiding_values(&self) -> Option<&[u16]> {
        match &self.hider {
            Some((_, r)) => Some(bytemuck::cast_slice(&self.map[r.clone()])),
            None => self.attribute(),
        }
    }

    /// For a set of species (`mask`: bit `s` for species index `s`; indices of 64 and
    /// more are never in it), per node (indexed as [`Self::nodes`]) which particles its
    /// subtree holds: [`BELOW_IN`] when some are of the set, [`BELOW_OUT`] when some are
    /// not, both for a mixed subtree. What a viewer hiding species needs: a cluster of
    /// hidden species only draws nothing, a mixed one must be opened. One pass over the
    /// species section and the node records, bottom up; the last result is kept.
    ///
    /// Node records not checked yet are read as they are: a corrupt child range (out of
    /// its level) makes its node mixed, which stays in bounds and only asks for the node
    /// to be opened, where [`Self::check_children`] refuses it.
    ///
    /// The pass reads the species section and every node record once (about 3 GB for
    /// 2×10^8 particles, a few seconds), which the lazy checks of [`Self::open`] avoid
    /// otherwise: a price paid only by views that hide species.
    pub fn species_below(&self, mask: u64) -> Arc<[u8]> {
        self.hidden_below(&HiddenSet::of_species(mask))
    }

    /// Per node (in the node table's order), the species every particle below it is
    /// of, or [`MIXED_SPECIES`] where they are of several: so that a renderer draws a
    /// cluster of one species in that species' colour exactly, not through the node's
    /// 8-bit linear mixture. One pass over the SPECIES section and the node records
    /// (about 3 GB for 2×10^8 particles), kept for the file's lifetime.
    pub fn pure_species(&self) -> Arc<[u16]> {
        self.pure_species
            .get_or_init(|| self.compute_pure_species().into())
            .clone()
    }

    fn compute_pure_species(&self) -> Vec<u16> {
        let one = |c: &[u16]| {
            let (&first, rest) = c.split_first()?;
            rest.iter().all(|&s| s == first).then_some(first)
        };
        self.fold_below(
            MIXED_SPECIES,
            |particles, species| {
                species
                    .get(particles)
                    .and_then(one)
                    .unwrap_or(MIXED_SPECIES)
            },
            |children| one(children).unwrap_or(MIXED_SPECIES),
        )
    }

    /// A value per node (in the node table's order) made bottom up: from the range of
    /// its particle children (with the SPECIES section) on the level above the
    /// particles, from its children's values above that; `unknown` where a record's
    /// children lie outside their level.
    fn fold_below<T: Copy>(
        &self,
        unknown: T,
        particles: impl Fn(Range<usize>, &[u16]) -> T,
        children: impl Fn(&[T]) -> T,
    ) -> Vec<T> {
        let (nodes, levels, species) = (self.nodes(), self.levels(), self.species());
        let mut out = vec![unknown; nodes.len()];
        let Some(last) = levels.len().checked_sub(1) else {
            return out;
        };
        for l in (0..last).rev() {
            let first = levels[l].node_first as usize;
            for i in 0..levels[l].point_count as usize {
                let id = first.saturating_add(i);
                let Some(n) = nodes.get(id) else { break };
                let a = n.child_first as usize;
                let b = a.saturating_add(n.child_count as usize);
                let value = if l + 1 == last {
                    particles(a..b, species)
                } else if b as u64 <= levels[l + 1].point_count {
                    let f = levels[l + 1].node_first as usize;
                    out.get(f.saturating_add(a)..f.saturating_add(b))
                        .map_or(unknown, &children)
                } else {
                    unknown
                };
                out[id] = value;
            }
        }
        out
    }

    /// [`Self::species_below`] for any [`HiddenSet`]: per node, [`BELOW_IN`] when some
    /// particle below is hidden, [`BELOW_OUT`] when some is not. With value ranges, the
    /// pass decodes the attribute section too.
    pub fn hidden_below(&self, set: &HiddenSet) -> Arc<[u8]> {
        let mut cache = self.species_below.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((m, kinds)) = &*cache {
            if m == set {
                return kinds.clone();
            }
        }
        let kinds: Arc<[u8]> = self.compute_hidden_below(set).into();
        *cache = Some((*set, kinds.clone()));
        kinds
    }

    /// `set` as this file's particles are tested against it: its ranges as the
    /// quantized values the file stores (none meet a file without an attribute).
    pub fn hidden_test(&self, set: &HiddenSet) -> HiddenTest {
        let mut test = HiddenTest {
            species: set.species,
            codes: [(0, 0); MAX_HIDDEN_RANGES],
            slots: [0; MAX_HIDDEN_RANGES],
            count: 0,
        };
        for (&r, &slot) in set.ranges().iter().zip(set.slots()) {
            if let Some(c) = self
                .slot_attribute(slot)
                .and_then(|(info, _)| info.codes(r))
            {
                test.codes[test.count] = c;
                test.slots[test.count] = slot;
                test.count += 1;
            }
        }
        test
    }

    /// Whether `test` hides particle `i` (its species and attribute values as stored;
    /// an index past the particles is not hidden).
    pub fn hides_particle(&self, test: &HiddenTest, i: usize) -> bool {
        let Some(&s) = self.species().get(i) else {
            return false;
        };
        if !test.by_value() {
            return test.hides(s, |_| None);
        }
        test.hides(s, |slot| {
            self.slot_attribute(slot)
                .and_then(|(_, v)| v?.get(i).copied())
        })
    }

    fn compute_hidden_below(&self, set: &HiddenSet) -> Vec<u8> {
        let test = self.hidden_test(set);
        // Each slot's values, looked up once.
        let values: Vec<Option<&[u16]>> = (0..=self.slot_hiders.len())
            .map(|slot| {
                self.slot_attribute(slot as u8)
                    .and_then(|(_, v)| v)
                    .filter(|_| test.by_value())
            })
            .collect();
        let of = |i: usize, s: u16| {
            let q = |slot: u8| {
                values
                    .get(usize::from(slot))
                    .copied()
                    .flatten()
                    .and_then(|v| v.get(i).copied())
            };
            if test.hides(s, q) {
                BELOW_IN
            } else {
                BELOW_OUT
            }
        };
        self.fold_below(
            BELOW_IN | BELOW_OUT,
            |particles, species| {
                let start = particles.start;
                species.get(particles).map_or(BELOW_IN | BELOW_OUT, |c| {
                    c.iter().zip(start..).fold(0, |k, (&s, i)| k | of(i, s))
                })
            },
            |children| children.iter().fold(0, |k, &c| k | c),
        )
    }

    /// Checks the records of nodes `range` of level `l` (indices on the level; the
    /// finest level has no records and always passes) against the level table, their
    /// parents and the file's species, as [`Self::open`] checks the top levels: the
    /// blocks of [`NODE_BLOCK`] nodes holding them, each once (their ancestors' blocks
    /// first). Safe to call from several threads. The first failure is also kept for
    /// [`Self::node_error`]; a block that failed fails again with that error.
    ///
    /// Within a block the children of consecutive nodes are checked to be consecutive;
    /// across blocks, against the neighbouring record as it is (checked or not), so that
    /// two checked nodes of different blocks could claim overlapping children where the
    /// records between them are corrupt. For node children [`Self::check_children`]
    /// rules that out (with the parents' order checked here); for particle children
    /// only a check of the whole level ([`Self::check_all_nodes`], `verify`) does.
    /// Either way every range stays within its level.
    pub fn check_nodes(&self, l: usize, range: Range<usize>) -> Result<(), FormatError> {
        let levels = self.levels();
        if l + 1 >= levels.len() || range.start >= range.end {
            return Ok(());
        }
        let count = levels[l].point_count as usize;
        if range.end > count {
            return Err(self.keep_error(FormatError::corrupt(
                &self.path,
                format!("level {l}"),
                format!(
                    "nodes {}..{} asked for, beyond its {count} nodes",
                    range.start, range.end
                ),
            )));
        }
        for b in range.start / NODE_BLOCK..=(range.end - 1) / NODE_BLOCK {
            match self.node_blocks[self.block_first[l] + b].load(Ordering::Acquire) {
                BLOCK_VALID => {}
                BLOCK_FAILED => return self.node_error(),
                _ => {
                    if let Err(e) = self.check_block(l, b) {
                        let e = self.keep_error(e);
                        self.node_blocks[self.block_first[l] + b]
                            .store(BLOCK_FAILED, Ordering::Release);
                        return Err(e);
                    }
                }
            }
        }
        Ok(())
    }

    /// [`Self::check_nodes`] for the children of node `id`, which must be a checked
    /// node: what a traversal calls before it reads them. Node children must also be
    /// `id`'s by their parent links, so that no two checked nodes share children.
    #[inline]
    pub fn check_children(&self, id: usize) -> Result<(), FormatError> {
        let Some(n) = self.nodes().get(id) else {
            return Err(self.keep_error(FormatError::corrupt(
                &self.path,
                format!("node {id}"),
                "no such node",
            )));
        };
        let l = usize::from(n.level) + 1;
        let first = n.child_first as usize;
        let end = first + n.child_count as usize;
        self.check_nodes(l, first..end)?;
        // (A checked node has at least one child; `end > first` keeps an unchecked one
        // from underflowing below.)
        let last = end.saturating_sub(1).max(first);
        // Node children: the first and the last must name `id` as their parent; their
        // parents being in order (checked with their blocks), so must every child
        // between them, and no other checked node can claim them.
        if l + 1 < self.level_count() && end > first {
            let at = self.levels()[l].node_first as usize;
            for k in [first, last] {
                let p = self.nodes()[at + k].parent as usize;
                if p != id {
                    let lists = self.nodes().get(p).is_some_and(|q| {
                        let children =
                            q.child_first as usize..q.child_first as usize + q.child_count as usize;
                        usize::from(q.level) + 1 == l && children.contains(&k)
                    });
                    let problem = if lists {
                        format!("claimed as a child by node {id} and by its parent {p}")
                    } else {
                        format!("parent {p} does not list it as a child")
                    };
                    return Err(self.keep_error(FormatError::corrupt(
                        &self.path,
                        format!("node {}", at + k),
                        problem,
                    )));
                }
            }
        }
        Ok(())
    }

    /// Checks every node record (what [`Self::open`] leaves to [`Self::check_nodes`]).
    /// Level by level, each on every core in contiguous runs of blocks; the error
    /// reported is that of the lowest failing run.
    pub fn check_all_nodes(&self) -> Result<(), FormatError> {
        let levels = self.levels();
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
        for l in 0..levels.len() - 1 {
            let count = levels[l].point_count as usize;
            let blocks = count.div_ceil(NODE_BLOCK);
            let runs = threads.min(blocks / 4).max(1);
            if runs == 1 {
                self.check_nodes(l, 0..count)?;
                continue;
            }
            let per = blocks.div_ceil(runs) * NODE_BLOCK;
            first_failure_of(runs, |k| {
                self.check_nodes(l, (k * per).min(count)..((k + 1) * per).min(count))
            })?;
        }
        Ok(())
    }

    /// The first failed [`Self::check_nodes`] or [`Self::check_children`], if any:
    /// whoever used records that the failing check left unread (a traversal stops at
    /// such nodes) reports it. It stays: a file found corrupt once reports it to every
    /// later caller, whichever part of it they read.
    pub fn node_error(&self) -> Result<(), FormatError> {
        match self.node_error.get() {
            None => Ok(()),
            Some((place, problem)) => Err(FormatError::corrupt(&self.path, place, problem)),
        }
    }

    fn keep_error(&self, e: FormatError) -> FormatError {
        let kept = match &e {
            FormatError::Corrupt { place, problem, .. } => (place.clone(), problem.clone()),
            other => ("node records".to_string(), other.to_string()),
        };
        let _ = self.node_error.set(kept);
        e
    }

    /// Checks block `b` of level `l` (see [`Self::check_nodes`]) in node order, each
    /// node's parent's block before it, since a node's checks read its ancestors'
    /// records: the first failure is the one an eager pass over the levels would find
    /// first among these nodes. A parent block is checked at most once, so however the
    /// parent links point, the work stays within the level above's blocks.
    fn check_block(&self, l: usize, b: usize) -> Result<(), FormatError> {
        let (nodes, levels) = (self.nodes(), self.levels());
        let first = levels[l].node_first as usize;
        let count = levels[l].point_count as usize;
        let range = b * NODE_BLOCK..((b + 1) * NODE_BLOCK).min(count);
        let rules = NodeRules {
            delta_n: self.delta_n(),
            species_count: self.metadata.species.len(),
            half_range: crate::quantize::half_range(self.position_bits()),
        };
        for i in range {
            // The parent's block first (once checked, one atomic load): the node's checks
            // read its ancestors' records. A parent outside the level above is the
            // node's own error, reported by its checks.
            if l > 0 {
                let pfirst = levels[l - 1].node_first as usize;
                let p = (nodes[first + i].parent as usize).wrapping_sub(pfirst);
                if p < levels[l - 1].point_count as usize {
                    self.check_nodes(l - 1, p..p + 1)?;
                }
            }
            check_node(&self.path, nodes, levels, rules, l, i)?;
            // Parents are in node order (children of consecutive nodes are consecutive):
            // with `check_children`'s test of a node's first and last child, no two
            // checked nodes share node children, whatever unchecked records lie between.
            // The predecessor is read as a number only (its block may be unchecked).
            if l > 0 && i > 0 {
                let (p, q) = (nodes[first + i].parent, nodes[first + i - 1].parent);
                if p < q {
                    return Err(FormatError::corrupt(
                        &self.path,
                        format!("node {}", first + i),
                        format!(
                            "parent {p} comes before its predecessor's parent {q} (node {}'s \
                             record, or this one's, is damaged)",
                            first + i - 1
                        ),
                    ));
                }
            }
        }
        self.node_blocks[self.block_first[l] + b].store(BLOCK_VALID, Ordering::Release);
        Ok(())
    }

    /// The nodes of level `l` (empty for the finest level).
    pub fn level_nodes(&self, l: usize) -> &[NodeRecord] {
        let lv = self.levels()[l];
        if l + 1 == self.level_count() {
            return &[];
        }
        &self.nodes()[lv.node_first as usize..(lv.node_first + lv.point_count) as usize]
    }

    /// Quantized positions of level `l` (empty for level 0, whose single point is node 0).
    #[inline]
    pub fn positions(&self, l: usize) -> Positions<'_> {
        let bytes = &self.map[self.positions[l].clone()];
        match self.header.position_bits {
            8 => Positions::U8(bytemuck::cast_slice(bytes)),
            _ => Positions::U16(bytemuck::cast_slice(bytes)),
        }
    }

    /// Species index of every particle. Values are checked only by [`verify`](Self::verify):
    /// look them up in the species table with `get`.
    #[inline]
    pub fn species(&self) -> &[u16] {
        bytemuck::cast_slice(&self.map[self.species_range.clone()])
    }

    /// Quantized attribute of every particle, when the file has one.
    pub fn attribute(&self) -> Option<&[u16]> {
        self.attribute_range
            .clone()
            .map(|r| bytemuck::cast_slice(&self.map[r]))
    }

    /// Quantized radius of every particle, when the file keeps them (decode with the
    /// metadata's `radius`, or [`Self::particle_radius`]).
    pub fn radii(&self) -> Option<&[u16]> {
        self.radius_range
            .clone()
            .map(|r| bytemuck::cast_slice(&self.map[r]))
    }

    /// The radius a value `q` of the file's RADIUS or RADIUS_LOG section stands for
    /// ([`RadiusInfo::decode`]; on a log scale through a table made once); 0 without
    /// per-particle radii.
    #[inline]
    pub fn radius_of(&self, q: u16) -> f32 {
        match self.metadata.radius {
            Some(info) if info.log => self
                .radius_table
                .get_or_init(|| (0..=u16::MAX).map(|q| info.decode(q)).collect())
                .get(usize::from(q))
                .copied()
                .unwrap_or(0.0),
            Some(info) => info.decode(q),
            None => 0.0,
        }
    }

    /// The radius of particle `i` (an index into the finest level) from its own size
    /// where the file keeps one, else its species' radius (0 for an index out of range).
    pub fn particle_radius(&self, i: usize) -> f32 {
        let meta = &self.metadata;
        if let Some(q) = self.radii() {
            return q.get(i).map_or(0.0, |&q| self.radius_of(q));
        }
        self.species()
            .get(i)
            .and_then(|&s| meta.species.get(usize::from(s)))
            .map_or(0.0, |s| s.radius)
    }

    /// The smallest and largest radius particles of species `s` are drawn at: its
    /// `radius_range` where the file keeps per-particle radii, else its radius twice
    /// (`[0, 0]` for no such species).
    pub fn species_radius_span(&self, s: usize) -> [f32; 2] {
        self.metadata
            .species
            .get(s)
            .map_or([0.0; 2], |sp| match (self.radii(), sp.radius_range) {
                (Some(_), Some(range)) => range,
                _ => [sp.radius; 2],
            })
    }

    /// [`Self::species_radius_span`] of species `s` drawn at radius `drawn` instead of its
    /// `radius` (a style's): each particle's size scaled alike.
    pub fn species_radius_span_at(&self, s: usize, drawn: f32) -> [f32; 2] {
        let own = self.metadata.species.get(s).map_or(0.0, |sp| sp.radius);
        if own > 0.0 {
            self.species_radius_span(s).map(|r| r * (drawn / own))
        } else {
            [drawn; 2]
        }
    }

    /// The smallest radius a particle of the file may have: the smallest of its species'
    /// sizes ([`Self::species_radius_span`]; infinite for a file of no species).
    pub fn min_particle_radius(&self) -> f32 {
        (0..self.metadata.species.len())
            .map(|s| self.species_radius_span(s)[0])
            .fold(f32::INFINITY, f32::min)
    }

    /// The largest radius a particle of the file may have: the radius range's end where
    /// the file keeps per-particle radii, else the largest species radius.
    pub fn max_particle_radius(&self) -> f32 {
        let species = self
            .metadata
            .species
            .iter()
            .map(|s| s.radius)
            .fold(0.0, f32::max);
        self.metadata
            .radius
            .as_ref()
            .map_or(species, |r| r.max.max(species))
    }

    /// For level `m ≥ 1`: the nodes that encode its points and, for each, the range of
    /// points it encodes, in order (the ranges tile the level).
    pub fn encoding_ranges(&self, m: usize) -> Result<Vec<(usize, Range<usize>)>, FormatError> {
        let ql = m.saturating_sub(self.delta_n());
        let levels = self.levels();
        for l in ql..m {
            self.check_nodes(l, 0..levels[l].point_count as usize)?;
        }
        let first = levels[ql].node_first as usize;
        let count = levels[ql].point_count as usize;
        // Descendant ranges of the level-ql nodes, pushed down one level at a time.
        let mut ranges: Vec<Range<usize>> = (0..count).map(|i| i..i + 1).collect();
        for l in ql..m {
            let lnodes = self.level_nodes(l);
            for r in &mut ranges {
                let a = &lnodes[r.start];
                let b = &lnodes[r.end - 1];
                *r = a.child_first as usize..(b.child_first + b.child_count) as usize;
            }
        }
        Ok(ranges
            .into_iter()
            .enumerate()
            .map(|(i, r)| (first + i, r))
            .collect())
    }

    /// Decodes every point of level `m ≥ 1`, in order (checking the node records it
    /// reads first).
    pub fn decode_level(&self, m: usize) -> Result<Vec<[f32; 3]>, FormatError> {
        let pos = self.positions(m);
        let nodes = self.nodes();
        let bits = self.position_bits();
        let mut out = Vec::with_capacity(pos.len());
        for (node, r) in self.encoding_ranges(m)? {
            let n = &nodes[node];
            for i in r {
                out.push(quantize::decode3(
                    pos.get(i),
                    n.centroid,
                    n.quant_scale,
                    bits,
                ));
            }
        }
        Ok(out)
    }

    /// Checks every section's checksum where the sections hold at most `max_bytes` in
    /// all (a small file: hashing it costs little beside drawing it), and returns whether
    /// it did. A file damaged on disk (a flipped byte in its positions) is then refused on
    /// open instead of drawn; a larger one is left to [`Self::verify`].
    pub fn check_checksums_up_to(&self, max_bytes: u64) -> Result<bool, FormatError> {
        let total = self
            .sections
            .iter()
            .fold(0u64, |t, s| t.saturating_add(s.length));
        if total > max_bytes {
            return Ok(false);
        }
        for i in 0..self.sections.len() {
            self.check_section(i)?;
        }
        Ok(true)
    }

    /// Checks the checksums of the sections of `kind`, whatever their size: a reader
    /// that counts over a whole section (`mdlod info`'s species counts) reads every byte
    /// of it anyway, and a flipped byte there gave wrong counts with no error.
    pub fn check_checksums_of(&self, kind: SectionKind) -> Result<(), FormatError> {
        for i in 0..self.sections.len() {
            if self.sections[i].kind == kind as u32 {
                self.check_section(i)?;
            }
        }
        Ok(())
    }

    /// Section `i`'s checksum against its bytes.
    fn check_section(&self, i: usize) -> Result<(), FormatError> {
        let s = &self.sections[i];
        let bytes = &self.map[s.offset as usize..(s.offset + s.length) as usize];
        let computed = xxh3_64(bytes);
        if computed != s.checksum {
            let name = SectionKind::from_code(s.kind).map_or("unknown", SectionKind::name);
            return Err(FormatError::Checksum {
                path: self.path.clone(),
                place: format!(
                    "section {i} ({name}, level {}) at offset {}",
                    s.level, s.offset
                ),
                stored: s.checksum,
                computed,
            });
        }
        Ok(())
    }

    /// Checks every section checksum, that the padding between sections is zero, every
    /// node's point range, every node's bounds (inside its parent's), every species index
    /// and every decoded point (finite, inside its parent's bounds up to the quantization
    /// step; a particle, inside them shrunk by its radius up to the recorded position
    /// error).
    pub fn verify(&self) -> Result<VerifyReport, FormatError> {
        let mut report = VerifyReport::default();
        self.check_checksums_up_to(u64::MAX)?;
        for s in &self.sections {
            report.sections += 1;
            report.bytes_hashed += s.length;
        }
        // The bytes outside the header, the sections and the table (alignment padding, and
        // anything after the table) are covered by no checksum; the spec makes them zero,
        // so a flipped one is found here.
        let mut spans: Vec<(usize, usize)> = self
            .sections
            .iter()
            .map(|s| (s.offset as usize, (s.offset + s.length) as usize))
            .collect();
        spans.push((0, HEADER_SIZE));
        let table_at = self.header.section_table_offset as usize;
        spans.push((table_at, table_at + 32 * self.sections.len()));
        spans.push((self.map.len(), self.map.len()));
        spans.sort_unstable();
        let mut covered = 0;
        for (start, end) in spans {
            if let Some(k) = self.map[covered.min(start)..start]
                .iter()
                .position(|&b| b != 0)
            {
                return Err(FormatError::corrupt(
                    &self.path,
                    format!("byte {}", covered + k),
                    "lies in no section (padding) but is not zero",
                ));
            }
            covered = covered.max(end);
        }
        // A RADIUS section is version 1.1's, RADIUS_LOG 1.2's: a file of an earlier minor
        // version holding one was not written by a writer of that version.
        let log = self.metadata.radius.is_some_and(|r| r.log);
        let (section, since) = if log {
            ("RADIUS_LOG", 2)
        } else {
            ("RADIUS", 1)
        };
        if self.extra_ranges.is_some() && self.header.version_minor < 2 {
            return Err(FormatError::corrupt(
                &self.path,
                "header",
                format!(
                    "version {}.{} holds an ATTRIBUTES section, which version 1.2 added",
                    self.header.version_major, self.header.version_minor
                ),
            ));
        }
        // Every extra attribute's node means are finite, as the first's are.
        for (k, a) in self.metadata.attributes.iter().enumerate() {
            if let Some(i) = self
                .extra_node_means(k)
                .and_then(|m| m.iter().position(|v| !v.is_finite()))
            {
                return Err(FormatError::corrupt(
                    &self.path,
                    format!("NODE_ATTRIBUTES, attribute {:?}, node {i}", a.name),
                    "mean is not finite",
                ));
            }
        }
        if self.radii().is_some() && self.header.version_minor < since {
            return Err(FormatError::corrupt(
                &self.path,
                "header",
                format!(
                    "version {}.{} holds a {section} section, which version 1.{since} added",
                    self.header.version_major, self.header.version_minor
                ),
            ));
        }
        let species_count = self.metadata.species.len();
        if let Some(i) = self
            .species()
            .iter()
            .position(|&s| usize::from(s) >= species_count)
        {
            return Err(FormatError::corrupt(
                &self.path,
                format!("SPECIES, particle {i}"),
                format!(
                    "species index {} but only {species_count} species",
                    self.species()[i]
                ),
            ));
        }
        // The node records open left to be checked block by block.
        self.check_all_nodes()?;
        let last = self.level_count() - 1;
        let nodes = self.nodes();
        // Every node's point range is its descendants on its point level: the first
        // descendant of its first child's line and the last of its last child's, node
        // by node (no table of ranges: a level may hold 10^8 nodes).
        for l in 0..last {
            let point_level = (l + self.delta_n()).min(last);
            let first = self.levels()[l].node_first as usize;
            for (i, n) in self.level_nodes(l).iter().enumerate() {
                let (mut a, mut b) = (i, i);
                for d in l..point_level {
                    let dnodes = self.level_nodes(d);
                    let (x, y) = (&dnodes[a], &dnodes[b]);
                    a = x.child_first as usize;
                    b = (y.child_first + y.child_count) as usize - 1;
                }
                if n.point_first as usize != a || n.point_count as usize != b + 1 - a {
                    return Err(FormatError::corrupt(
                        &self.path,
                        format!("node {}", first + i),
                        format!(
                            "points {}+{} on level {point_level}, but its descendants there are {}+{}",
                            n.point_first,
                            n.point_count,
                            a,
                            b + 1 - a
                        ),
                    ));
                }
            }
        }
        // Every point, decoded by its parent's encoding node as it is read (no copy of
        // the level), lies within its parent's bounds up to the quantization step. A
        // particle, more tightly: its parent's bounds are those of its particles'
        // spheres, so its decoded centre lies inside them shrunk by its radius, up to
        // the recorded position error and the bounds' single-precision rounding.
        let bits = self.position_bits();
        let error = self.metadata.max_position_error;
        for m in 1..=last {
            let positions = self.positions(m);
            let parents = self.level_nodes(m - 1);
            for (pi, parent) in parents.iter().enumerate() {
                let r =
                    parent.child_first as usize..(parent.child_first + parent.child_count) as usize;
                // The step of the encoding node bounds how far rounding may move a point.
                let enc = &nodes[self.encoding_node_of_children(m, pi)];
                let slack = enc
                    .quant_scale
                    .iter()
                    .map(|s| f64::from(*s))
                    .fold(0.0, f64::max);
                // A node's box lies inside its parent's: the parent's bounds hold every
                // particle sphere below it, so the child's, which hold some of them, do
                // (up to single-precision rounding). A traversal culls a subtree by its
                // top's box, so a parent's box narrower than its children's would drop
                // particles from the picture without any other check failing.
                if m < last {
                    let children = self.level_nodes(m);
                    for i in r.clone() {
                        let Some(c) = children.get(i) else { continue };
                        let mut past = 0.0f64;
                        let mut size = 0.0f64;
                        for k in 0..3 {
                            let (lo, hi) = (
                                f64::from(parent.bounds_min[k]),
                                f64::from(parent.bounds_max[k]),
                            );
                            let (clo, chi) =
                                (f64::from(c.bounds_min[k]), f64::from(c.bounds_max[k]));
                            past = past.max(lo - clo).max(chi - hi);
                            size = size.max(lo.abs()).max(hi.abs());
                        }
                        if past > 8.0 * f64::from(f32::EPSILON) * size.max(1.0) {
                            return Err(FormatError::corrupt(
                                &self.path,
                                format!("node {}", self.levels()[m].node_first as usize + i),
                                format!(
                                    "its bounds reach {past:.3e} past those of its parent node {} on \
                                     level {}, which must hold every particle sphere below it",
                                    self.levels()[m - 1].node_first as usize + pi,
                                    m - 1
                                ),
                            ));
                        }
                    }
                }
                for i in r {
                    let p =
                        quantize::decode3(positions.get(i), enc.centroid, enc.quant_scale, bits);
                    if p.iter().any(|v| !v.is_finite()) {
                        return Err(FormatError::corrupt(
                            &self.path,
                            format!("level {m}, point {i}"),
                            "decodes to a non-finite position",
                        ));
                    }
                    let mut outside = 0.0f64;
                    for ((&v, &lo), &hi) in p.iter().zip(&parent.bounds_min).zip(&parent.bounds_max)
                    {
                        let (v, lo, hi) = (f64::from(v), f64::from(lo), f64::from(hi));
                        outside = outside.max(lo - v).max(v - hi);
                    }
                    let excess = outside - slack;
                    report.max_outside_parent_bounds =
                        report.max_outside_parent_bounds.max(outside.max(0.0));
                    if excess > 1e-3 * (1.0 + f64::from(parent.radius)) {
                        return Err(FormatError::corrupt(
                            &self.path,
                            format!("level {m}, point {i}"),
                            format!(
                                "decodes to [{}, {}, {}], {outside:.3e} outside the bounds of its \
                                 parent node {} on level {}",
                                shown(p[0]),
                                shown(p[1]),
                                shown(p[2]),
                                self.levels()[m - 1].node_first as usize + pi,
                                m - 1
                            ),
                        ));
                    }
                    if m == last {
                        // The particle's own radius where the file keeps one, within its
                        // species' sizes up to a quantization step.
                        let r = f64::from(self.particle_radius(i));
                        if let Some(info) = &self.metadata.radius {
                            let s = self.species().get(i).copied().unwrap_or(0);
                            let [lo, hi] = self.species_radius_span(usize::from(s));
                            let (lo, hi) = (f64::from(lo), f64::from(hi));
                            let slack = info.step_at(hi) + 8.0 * f64::from(f32::EPSILON) * hi;
                            if r < lo - slack || r > hi + slack {
                                let section = if info.log { "RADIUS_LOG" } else { "RADIUS" };
                                return Err(FormatError::corrupt(
                                    &self.path,
                                    format!("{section}, particle {i}"),
                                    format!(
                                        "radius {} lies outside its species' sizes {} to {}",
                                        shown(r as f32),
                                        shown(lo as f32),
                                        shown(hi as f32)
                                    ),
                                ));
                            }
                        }
                        let mut beyond = 0.0f64;
                        let mut wider = 0.0f64;
                        let mut size = r;
                        for ((&v, &lo), &hi) in
                            p.iter().zip(&parent.bounds_min).zip(&parent.bounds_max)
                        {
                            let (v, lo, hi) = (f64::from(v), f64::from(lo), f64::from(hi));
                            // A box narrower than the sphere (rounding, tiny radii) leaves
                            // the centre its middle.
                            let (a, b) = if hi - lo >= 2.0 * r {
                                (lo + r, hi - r)
                            } else {
                                ((lo + hi) / 2.0, (lo + hi) / 2.0)
                            };
                            beyond = beyond.max(a - v).max(v - b);
                            wider = wider.max(2.0 * r - (hi - lo));
                            size = size.max(lo.abs()).max(hi.abs());
                        }
                        let rounding = 8.0 * f64::from(f32::EPSILON) * size;
                        // The bounds hold every particle's sphere: one wider than them
                        // (beyond rounding) is a radius the bounds were not made for.
                        if wider > 2.0 * (error + rounding) {
                            return Err(FormatError::corrupt(
                                &self.path,
                                format!("level {m}, particle {i}"),
                                format!(
                                    "its sphere (radius {}) is {wider:.3e} wider than its \
                                     parent node's bounds on an axis",
                                    shown(r as f32)
                                ),
                            ));
                        }
                        if beyond > error + rounding {
                            return Err(FormatError::corrupt(
                                &self.path,
                                format!("level {m}, particle {i}"),
                                format!(
                                    "decodes {beyond:.3e} beyond where its parent node's bounds \
                                     put its centre, more than the recorded position error \
                                     {error:.3e}"
                                ),
                            ));
                        }
                        report.max_particle_error_seen = report.max_particle_error_seen.max(beyond);
                    }
                }
                report.points_decoded += u64::from(parent.child_count);
            }
        }
        Ok(report)
    }

    /// Which field of the metadata JSON `bytes` (already read as [`Metadata`]) that FORMAT.md
    /// makes an object is something else, if any.
    fn not_an_object(bytes: &[u8]) -> Option<String> {
        let v: serde_json::Value = serde_json::from_slice(bytes).ok()?;
        let field = |v: &serde_json::Value, key: &str, name: &str| {
            v.get(key)
                .filter(|f| !(f.is_object() || f.is_null()))
                .map(|_| format!("`{name}` is not an object (section 7 of FORMAT.md)"))
        };
        for key in [
            "box",
            "attribute",
            "radius",
            "radius_log",
            "source",
            "build",
        ] {
            if let Some(p) = field(&v, key, key) {
                return Some(p);
            }
        }
        if let Some(p) = v
            .get("source")
            .and_then(|s| field(s, "bytes", "source.bytes"))
        {
            return Some(p);
        }
        if let Some(i) = v
            .get("attributes")
            .and_then(|a| a.as_array())
            .and_then(|a| a.iter().position(|e| !e.is_object()))
        {
            return Some(format!(
                "attributes[{i}] is not an object (section 7 of FORMAT.md)"
            ));
        }
        let species = v.get("species")?.as_array()?;
        species
            .iter()
            .position(|s| !s.is_object())
            .map(|i| format!("species {i} is not an object (section 7 of FORMAT.md)"))
    }

    /// The node encoding the children of point `pi` of level `m - 1`.
    fn encoding_node_of_children(&self, m: usize, pi: usize) -> usize {
        // Walk up from the parent (level m-1) to level max(0, m - delta_n).
        let ql = m.saturating_sub(self.delta_n());
        let levels = self.levels();
        let mut node = levels[m - 1].node_first as usize + pi;
        let nodes = self.nodes();
        for _ in ql..m - 1 {
            node = nodes[node].parent as usize;
        }
        node
    }
}

/// Checks every node record against the level table; linear in the node count. Large
/// levels are checked in chunks on several threads; each node's checks need only the
/// records around it (its predecessor's children end where its own begin, when every
/// node before it passed), so the first error reported is the one a single pass in
/// index order finds.
/// What a node record is checked against beside its neighbours: the file's δn, its
/// species count, and the half range of its quantized offsets (0: the encoding scale is
/// not checked against the node's bounds).
#[derive(Clone, Copy, Debug)]
struct NodeRules {
    delta_n: usize,
    species_count: usize,
    half_range: f32,
}

fn validate_nodes(
    path: &Path,
    nodes: &[NodeRecord],
    levels: &[LevelRecord],
    rules: NodeRules,
    eager_levels: usize,
) -> Result<(), FormatError> {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    validate_nodes_in(path, nodes, levels, rules, threads, 1 << 18, eager_levels)
}

/// [`validate_nodes`] on up to `threads` threads, in chunks of at least `chunk_min` nodes,
/// for the first `eager_levels` levels (the others' ends only).
#[allow(clippy::too_many_arguments)]
fn validate_nodes_in(
    path: &Path,
    nodes: &[NodeRecord],
    levels: &[LevelRecord],
    rules: NodeRules,
    threads: usize,
    chunk_min: usize,
    eager_levels: usize,
) -> Result<(), FormatError> {
    let last = levels.len() - 1;
    for l in 0..last {
        let count = levels[l].point_count as usize;
        if l >= eager_levels {
            // Checked block by block later; only the level's end against the next
            // level's count now (one record read).
            check_level_end(path, nodes, levels, l)?;
            continue;
        }
        let check = |range: std::ops::Range<usize>| {
            range
                .into_iter()
                .try_for_each(|i| check_node(path, nodes, levels, rules, l, i))
        };
        let chunks = if count >= 2 * chunk_min {
            threads.min(count / chunk_min).max(1)
        } else {
            1
        };
        if chunks == 1 {
            check(0..count)?;
        } else {
            let per = count.div_ceil(chunks);
            // The first failing chunk holds the first failing node.
            first_failure_of(chunks, |k| check(k * per..((k + 1) * per).min(count)))?;
        }
        check_level_end(path, nodes, levels, l)?;
    }
    Ok(())
}

/// Runs `run(k)` for `k` in `0..runs`, each on a scoped thread of its own, and returns
/// the failure of the lowest failing `k`: what running them in order would return.
fn first_failure_of<F>(runs: usize, run: F) -> Result<(), FormatError>
where
    F: Fn(usize) -> Result<(), FormatError> + Sync,
{
    let results: Vec<Result<(), FormatError>> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..runs)
            .map(|k| {
                let run = &run;
                scope.spawn(move || run(k))
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
            .collect()
    });
    results.into_iter().collect()
}

/// The children of level `l`'s last node end where level `l + 1` does.
fn check_level_end(
    path: &Path,
    nodes: &[NodeRecord],
    levels: &[LevelRecord],
    l: usize,
) -> Result<(), FormatError> {
    let first = levels[l].node_first as usize;
    let count = levels[l].point_count as usize;
    let next_count = levels[l + 1].point_count;
    let expected_child = match count {
        0 => 0,
        _ => {
            let n = &nodes[first + count - 1];
            u64::from(n.child_first) + u64::from(n.child_count)
        }
    };
    if expected_child != next_count {
        return Err(FormatError::corrupt(
            path,
            format!("level {l}"),
            format!(
                "nodes have {expected_child} children but level {} holds {next_count} points",
                l + 1
            ),
        ));
    }
    Ok(())
}

/// The checks of node `i` of level `l` (see [`validate_nodes`]), assuming the nodes
/// before it on its level passed theirs.
#[allow(clippy::too_many_arguments)]
fn check_node(
    path: &Path,
    nodes: &[NodeRecord],
    levels: &[LevelRecord],
    rules: NodeRules,
    l: usize,
    i: usize,
) -> Result<(), FormatError> {
    let NodeRules {
        delta_n,
        species_count,
        half_range,
    } = rules;
    let last = levels.len() - 1;
    let bad =
        |id: usize, problem: String| FormatError::corrupt(path, format!("node {id}"), problem);
    let first = levels[l].node_first as usize;
    let next_count = levels[l + 1].point_count;
    let id = first + i;
    // The children so far: where the previous node's end (it passed its checks).
    let mut expected_child: u64 = if i == 0 {
        0
    } else {
        let p = &nodes[id - 1];
        u64::from(p.child_first) + u64::from(p.child_count)
    };
    let n = &nodes[id];
    if usize::from(n.level) != l {
        return Err(bad(id, format!("level {} (it lies on level {l})", n.level)));
    }
    if u64::from(n.child_first) != expected_child || n.child_count == 0 {
        return Err(bad(id, format!(
            "children {}+{} do not continue the previous node's (expected first {expected_child}, count ≥ 1)",
            n.child_first, n.child_count
        )));
    }
    expected_child += u64::from(n.child_count);
    if expected_child > next_count {
        return Err(bad(
            id,
            format!(
                "children end at {expected_child}, beyond the {next_count} points of level {}",
                l + 1
            ),
        ));
    }
    let point_level = (l + delta_n).min(last);
    if usize::from(n.point_level) != point_level {
        return Err(bad(
            id,
            format!("point level {} (expected {point_level})", n.point_level),
        ));
    }
    let pl_count = levels[point_level].point_count;
    if u64::from(n.point_first) + u64::from(n.point_count) > pl_count || n.point_count == 0 {
        return Err(bad(
            id,
            format!(
                "points {}+{} outside the {pl_count} points of level {point_level}",
                n.point_first, n.point_count
            ),
        ));
    }
    if l == 0 {
        if n.parent != u32::MAX {
            return Err(bad(id, "top node has a parent".into()));
        }
    } else {
        let p = n.parent as usize;
        let pfirst = levels[l - 1].node_first as usize;
        let ok = p >= pfirst
            && p < first
            && (nodes[p].child_first as usize
                ..(nodes[p].child_first + nodes[p].child_count) as usize)
                .contains(&i);
        if !ok {
            return Err(bad(id, format!("parent {p} does not list it as a child")));
        }
    }
    // Encoding node: the ancestor on level max(0, point_level - delta_n).
    let ql = point_level.saturating_sub(delta_n);
    let mut anc = id;
    for _ in ql..l {
        anc = nodes[anc].parent as usize;
    }
    if n.quant_node as usize != anc {
        return Err(bad(
            id,
            format!(
                "encoding node {} (expected its ancestor {anc} on level {ql})",
                n.quant_node
            ),
        ));
    }
    let floats = n
        .centroid
        .iter()
        .chain(&n.quant_scale)
        .chain(&n.bounds_min)
        .chain(&n.bounds_max)
        .chain([&n.radius, &n.area_sum, &n.attribute, &n.rms_radius]);
    let mut finite = true;
    for v in floats {
        finite &= v.is_finite();
    }
    if !finite || n.radius < 0.0 || n.quant_scale.iter().any(|s| *s < 0.0) || n.area_sum < 0.0 {
        return Err(bad(id, geometry_problem(n)));
    }
    if (0..3).any(|k| n.bounds_min[k] > n.bounds_max[k]) {
        return Err(bad(id, "bounds_min exceeds bounds_max".into()));
    }
    // The points a node encodes lie inside its bounds, so a writer's scale spreads at
    // most the bounds' reach from the centroid over the code range (`scale_for`); twice
    // that is allowed. A forged scale would put decoded points anywhere (kernels and
    // splats of any size, a render that never ends).
    if let Some(k) = (0..3).find(|&k| {
        let reach = (n.bounds_max[k] - n.centroid[k]).max(n.centroid[k] - n.bounds_min[k]);
        n.quant_scale[k] * half_range > 2.0 * reach.max(0.0) + f32::EPSILON * n.centroid[k].abs()
    }) {
        return Err(bad(
            id,
            format!(
                "quantization scale {:e} on axis {k} spreads its points past twice its \
                 bounds' reach from its centroid",
                n.quant_scale[k]
            ),
        ));
    }
    if usize::from(n.species) >= species_count {
        return Err(bad(id, format!("species {} of {species_count}", n.species)));
    }
    Ok(())
}

/// `v` as a message shows it: in full where that is short, else in exponent form (a
/// damaged file's 3·10^38 is not 39 digits).
fn shown(v: f32) -> String {
    if v == 0.0 || (1e-4..1e7).contains(&v.abs()) || !v.is_finite() {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// Which of node record `n`'s numbers is non-finite or negative where it must not be
/// (the first found), for [`check_node`]'s error.
fn geometry_problem(n: &NodeRecord) -> String {
    let one = std::slice::from_ref;
    let fields: [(&str, &[f32]); 8] = [
        ("centroid", &n.centroid),
        ("quant_scale", &n.quant_scale),
        ("bounds_min", &n.bounds_min),
        ("bounds_max", &n.bounds_max),
        ("radius", one(&n.radius)),
        ("area_sum", one(&n.area_sum)),
        ("attribute", one(&n.attribute)),
        ("rms_radius", one(&n.rms_radius)),
    ];
    let named = |name: &str, values: &[f32], k: usize| match values.len() {
        1 => name.to_string(),
        _ => format!("{name}.{}", ["x", "y", "z"][k.min(2)]),
    };
    for (name, values) in fields {
        if let Some(k) = values.iter().position(|v| !v.is_finite()) {
            return format!(
                "{} is {} (must be finite)",
                named(name, values, k),
                values[k]
            );
        }
    }
    for (name, values) in [fields[1], fields[4], fields[5]] {
        if let Some(k) = values.iter().position(|v| *v < 0.0) {
            return format!(
                "{} is {:e} (must not be negative)",
                named(name, values, k),
                values[k]
            );
        }
    }
    "non-finite or negative geometry".into()
}

/// The attribute of `names` (a file's [`MdlodFile::attribute_names`]) that `name` asks
/// for: the name as stored, or its last part where that is one attribute's only (`mass`
/// for a GSD input's `particles/mass`); `None` when no attribute answers to it.
pub fn attribute_named<'a>(names: &[&'a str], name: &str) -> Option<&'a str> {
    if let Some(exact) = names.iter().find(|n| **n == name) {
        return Some(exact);
    }
    // A column kept as its logarithm by the column's own name (`sigma` for
    // `log10(sigma)`), as the conversion was asked for it.
    if let Some(logged) = names.iter().find(|n| {
        n.strip_prefix("log10(")
            .and_then(|s| s.strip_suffix(')'))
            .is_some_and(|inner| inner == name)
    }) {
        return Some(logged);
    }
    // A magnitude (`|particles/velocity|`) and a logarithm (`log10(particles/mass)`) by
    // the last part of what they wrap too (`|velocity|`, `log10(mass)`).
    fn unwrapped(s: &str) -> (bool, bool, &str) {
        let (log, s) = match s.strip_prefix("log10(").and_then(|s| s.strip_suffix(')')) {
            Some(inner) => (true, inner),
            None => (false, s),
        };
        match s.strip_prefix('|').and_then(|s| s.strip_suffix('|')) {
            Some(inner) => (log, true, inner),
            None => (log, false, s),
        }
    }
    let asked = unwrapped(name);
    // The same logarithm first; then, for a name asked without one, a column kept as its
    // logarithm (`|velocity|` for `log10(|particles/velocity|)`, as `sigma` finds
    // `log10(sigma)` above).
    let by_part = |logged: bool| {
        let mut found = names.iter().filter(move |stored| {
            let (log, bars, inner) = unwrapped(stored);
            (log, bars) == (logged, asked.1)
                && inner
                    .rsplit_once('/')
                    .is_some_and(|(_, last)| last == asked.2)
        });
        match (found.next(), found.next()) {
            (Some(one), None) => Some(*one),
            _ => None,
        }
    };
    by_part(asked.0).or_else(|| (!asked.0).then(|| by_part(true)).flatten())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The checksum's test vectors that FORMAT.md gives implementers (inputs short,
    /// mid-length and past 240 bytes take different paths through XXH3).
    #[test]
    fn checksum_matches_the_test_vectors_the_spec_gives() {
        let long: Vec<u8> = (0..1024).map(|i| i as u8).collect();
        assert_eq!(xxh3_64(b""), 0x2d06_8005_38d3_94c2);
        assert_eq!(xxh3_64(b"abc"), 0x78af_5f94_892f_3950);
        assert_eq!(xxh3_64(&long), 0xa870_f929_8439_8d22);
        let spec = include_str!("../../FORMAT.md");
        for v in [
            "0x2d06800538d394c2",
            "0x78af5f94892f3950",
            "0xa870f92984398d22",
        ] {
            assert!(spec.contains(v), "FORMAT.md lacks {v}");
        }
    }

    #[test]
    fn attributes_are_found_by_name_or_last_part_and_magnitudes_alike() {
        let names = ["particles/mass", "|particles/velocity|", "c_pe", "|v|"];
        assert_eq!(attribute_named(&names, "mass"), Some("particles/mass"));
        assert_eq!(attribute_named(&names, "c_pe"), Some("c_pe"));
        assert_eq!(
            attribute_named(&names, "|velocity|"),
            Some("|particles/velocity|")
        );
        assert_eq!(attribute_named(&names, "|v|"), Some("|v|"));
        assert_eq!(attribute_named(&names, "velocity"), None);
        assert_eq!(attribute_named(&names, "|mass|"), None);
        let logs = ["log10(|particles/velocity|)", "log10(particles/mass)"];
        assert_eq!(
            attribute_named(&logs, "log10(|velocity|)"),
            Some("log10(|particles/velocity|)")
        );
        assert_eq!(
            attribute_named(&logs, "log10(mass)"),
            Some("log10(particles/mass)")
        );
        // By the last part and without the logarithm, as `sigma` finds `log10(sigma)`;
        // a column kept as it is first.
        assert_eq!(
            attribute_named(&logs, "|velocity|"),
            Some("log10(|particles/velocity|)")
        );
        assert_eq!(
            attribute_named(&logs, "mass"),
            Some("log10(particles/mass)")
        );
        let both = ["log10(|particles/velocity|)", "|particles/velocity|"];
        assert_eq!(
            attribute_named(&both, "|velocity|"),
            Some("|particles/velocity|")
        );
        // A column kept as its logarithm, by the column's own name; a column kept as it
        // is first.
        let kept = ["c_pe", "log10(sigma)", "log10(rho)", "rho"];
        assert_eq!(attribute_named(&kept, "sigma"), Some("log10(sigma)"));
        assert_eq!(attribute_named(&kept, "rho"), Some("rho"));
        assert_eq!(attribute_named(&kept, "sig"), None);
    }

    /// A valid three-level hierarchy: a top node over `n` nodes, each over 2 particles.
    fn hierarchy(n: usize) -> (Vec<NodeRecord>, Vec<LevelRecord>) {
        let level = |point_count: usize, node_first: usize| LevelRecord {
            point_count: point_count as u64,
            node_first: node_first as u64,
            reserved: [0; 2],
        };
        let levels = vec![level(1, 0), level(n, 1), level(2 * n, 1 + n)];
        let node = |level: u8, child_first: usize, child_count: usize, parent: u32| NodeRecord {
            centroid: [0.0; 3],
            radius: 1.0,
            quant_scale: [0.1; 3],
            area_sum: 1.0,
            bounds_min: [0.0; 3],
            attribute: 0.0,
            bounds_max: [1.0; 3],
            colour: 0,
            child_first: child_first as u32,
            child_count: child_count as u32,
            point_first: child_first as u32,
            point_count: child_count as u32,
            parent,
            quant_node: 0,
            rms_radius: 0.5,
            level,
            point_level: level + 1,
            species: 0,
        };
        let mut nodes = vec![node(0, 0, n, u32::MAX)];
        // A node encodes its own children (δn = 1).
        nodes.extend((0..n).map(|i| NodeRecord {
            quant_node: 1 + i as u32,
            ..node(1, 2 * i, 2, 0)
        }));
        (nodes, levels)
    }

    #[test]
    fn chunked_validation_reports_the_first_error_a_single_pass_finds() {
        let path = Path::new("h.mdlod");
        let n = 1000;
        let (nodes, levels) = hierarchy(n);
        let run = |nodes: &[NodeRecord], threads, chunk_min| {
            let rules = NodeRules {
                delta_n: 1,
                species_count: 1,
                half_range: 0.0,
            };
            validate_nodes_in(path, nodes, &levels, rules, threads, chunk_min, usize::MAX)
                .err()
                .map(|e| e.to_string())
        };
        assert_eq!(run(&nodes, 4, 16), None);
        assert_eq!(run(&nodes, 1, usize::MAX / 4), None);
        // Corruptions in several chunks: each pass reports the one at the lowest node,
        // with the message a single pass gives.
        type Corrupt = fn(&mut NodeRecord);
        let corruptions: [(usize, Corrupt); 5] = [
            (700, |r| r.child_count = 3),
            (350, |r| r.radius = f32::NAN),
            (351, |r| r.child_first += 1),
            (900, |r| r.species = 7),
            (10, |r| r.bounds_min[1] = 2.0),
        ];
        let mut bad = nodes.clone();
        for (k, (i, corrupt)) in corruptions.iter().enumerate() {
            corrupt(&mut bad[1 + i]);
            let single = run(&bad, 1, usize::MAX / 4).expect("an error");
            // The first corrupted node, or (a child count) its successor.
            let lowest = 1 + corruptions[..=k].iter().map(|c| c.0).min().unwrap_or(0);
            assert!(
                [lowest, lowest + 1]
                    .iter()
                    .any(|id| single.contains(&format!("node {id}:"))),
                "{single}"
            );
            for (threads, chunk_min) in [(2, 16), (4, 100), (8, 1)] {
                assert_eq!(
                    run(&bad, threads, chunk_min).as_deref(),
                    Some(single.as_str())
                );
            }
        }
        // A level whose children fall short of the next level: found after the chunks.
        let mut short = nodes.clone();
        short[n].child_count = 1;
        let single = run(&short, 1, usize::MAX / 4).expect("an error");
        assert!(single.contains("level 1"), "{single}");
        assert_eq!(run(&short, 4, 16).as_deref(), Some(single.as_str()));
    }
}
