//! Corrupt and hostile `.mdlod` files: every one must give a `FormatError` whose message
//! names the file and the place (header, section, level, node, particle, byte), never a
//! panic, and never be accepted in a state the accessors would later index out of bounds.
//!
//! A valid file is made with `convert_frame`; the damaged variants are made by flipping
//! bytes, truncating, patching the header or section table and recomputing the checksums
//! (so only the structural checks can catch them), or by rewriting whole sections through
//! `mdlod_format::Writer`.

use std::io::{Seek, SeekFrom, Write};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use std::time::Instant;

use mdlod_format::layout::{Header, LevelRecord, NodeRecord, SectionEntry};
use mdlod_format::{FormatError, MdlodFile, SectionKind, Writer};
use mdlod_preprocess::convert::{convert_frame, ConvertOptions};
use mdlod_preprocess::hierarchy::BuildParams;
use mdlod_preprocess::{Attribute, Frame, NoProgress, SpeciesName};
use xxhash_rust::xxh3::xxh3_64;

// ---------------------------------------------------------------------------------------
// A valid file.

/// An FCC slab of `n × n × n/2` cells (two species) with a sparse cloud above it, a
/// scalar attribute, and particles of their own sizes (the cloud's `Ag` from 1 to 2):
/// `2 n³ + 200` particles.
fn test_frame(n: usize) -> Frame {
    let (nz, ny) = (n / 2, n);
    let mut positions = mdlod_datasets::fcc_block([n, n, nz], 3.615);
    // Species by unit cell (i, j, k): site s lies in cell s / 4, k innermost.
    let mut species_index: Vec<u16> = (0..positions.len())
        .map(|s| {
            let c = s / 4;
            let (i, j, k) = (c / (nz * ny), (c / nz) % ny, c % nz);
            u16::from((i + 2 * j + k) % 5 == 0)
        })
        .collect();
    let mut s = 0x2545F4914F6CDD1Du64;
    let mut r = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut radii = vec![1.44f32; positions.len()];
    for _ in 0..200 {
        positions.push([r() * 40.0, r() * 40.0, 30.0 + r() * 40.0]);
        species_index.push(1);
        radii.push(1.0 + r());
    }
    let values = positions.iter().map(|p| p[0] - 0.25 * p[2]).collect();
    Frame {
        species_index,
        species: ["Cu", "Ag"]
            .map(|name| SpeciesName {
                name: name.into(),
                numeric_type: false,
                radius: (name == "Ag").then_some(1.44),
                radius_range: (name == "Ag").then_some((1.0, 2.0)),
                ..Default::default()
            })
            .to_vec(),
        attribute: Some(Attribute {
            name: "c_pe".into(),
            values,
        }),
        radii: Some(radii),
        timestep: Some(42),
        positions,
        ..Default::default()
    }
}

/// The bytes of a valid file of about 2200 particles in five or so levels.
fn valid_bytes(params: BuildParams) -> Vec<u8> {
    valid_bytes_of(10, params)
}

/// The bytes of a valid file of `2 n³ + 200` particles.
fn valid_bytes_of(n: usize, params: BuildParams) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("valid.mdlod");
    let opts = ConvertOptions {
        build: params,
        radii: vec![],
        ..Default::default()
    };
    convert_frame(&test_frame(n), None, &path, &opts, &NoProgress).unwrap();
    std::fs::read(&path).unwrap()
}

fn params_u16_delta1() -> BuildParams {
    BuildParams {
        max_root_points: 16,
        ..Default::default()
    }
}

fn params_u8_delta2() -> BuildParams {
    BuildParams {
        max_cluster_size: 6,
        max_root_points: 12,
        delta_n: 2,
        position_bits: 8,
    }
}

// ---------------------------------------------------------------------------------------
// Opening, and judging the outcome.

/// Every accessor of an opened file, as a renderer or `mdlod info` would use them.
fn touch_everything(f: &MdlodFile) -> Result<(), FormatError> {
    let _ = (f.path(), f.header(), f.sections().len(), f.metadata());
    let _ = (
        f.position_bits(),
        f.delta_n(),
        f.particle_count(),
        f.nodes().len(),
    );
    for l in 0..f.level_count() {
        let _ = f.levels()[l];
        let _ = f.level_nodes(l).len();
        let p = f.positions(l);
        if !p.is_empty() {
            let _ = (p.get(0), p.get(p.len() - 1), p.bytes().len());
        }
        if l >= 1 {
            let covered: usize = f.encoding_ranges(l)?.iter().map(|(_, r)| r.len()).sum();
            assert_eq!(covered, p.len());
            assert_eq!(f.decode_level(l)?.len(), p.len());
        }
    }
    let _ = (f.species().len(), f.attribute().map(<[u16]>::len));
    Ok(())
}

fn panic_text(p: Box<dyn std::any::Any + Send>) -> String {
    p.downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "(non-string panic)".into())
}

/// How much of the node table open checks: all of it (what files of up to
/// `EAGER_NODES` nodes get), or the top node alone, the rest block by block as the
/// accessors and `verify` reach them (what larger files get).
const OPEN_MODES: [(u64, &str); 2] = [(u64::MAX, "checked on open"), (1, "checked lazily")];

/// Opens (checking the records of at most `eager_nodes` nodes on open), verifies and
/// (with `touch`) uses every accessor; a panic becomes `Err(text)`.
fn outcome(path: &Path, touch: bool, eager_nodes: u64) -> Result<Result<(), FormatError>, String> {
    catch_unwind(AssertUnwindSafe(|| {
        let f = MdlodFile::open_with_eager_nodes(path, eager_nodes)?;
        if touch {
            touch_everything(&f)?;
        }
        f.verify().map(|_| ())
    }))
    .map_err(panic_text)
}

/// Asserts that `path` is refused with a message naming the file and containing `wants`,
/// whether open checks the node table or leaves it to be checked as it is read.
#[track_caller]
fn expect_refused(path: &Path, wants: &[&str]) -> String {
    let name = path.file_name().unwrap().to_str().unwrap();
    let mut first = None;
    for (eager, mode) in OPEN_MODES {
        match outcome(path, true, eager) {
            Err(p) => panic!("{name} ({mode}): the reader panicked: {p}"),
            Ok(Ok(())) => panic!("{name} ({mode}): accepted"),
            Ok(Err(e)) => {
                let msg = e.to_string();
                assert!(
                    msg.contains(name),
                    "{name} ({mode}): message does not name it: {msg}"
                );
                // Open checks where every level's nodes end before it checks a block of
                // a lazily checked level: a corrupt child count can be reported there.
                let level_end = eager != u64::MAX && msg.contains("children but level");
                for w in wants.iter().filter(|_| !level_end) {
                    assert!(
                        msg.contains(w),
                        "{name} ({mode}): message lacks {w:?}: {msg}"
                    );
                }
                first.get_or_insert(msg);
            }
        }
    }
    first.unwrap_or_default()
}

#[track_caller]
fn expect_accepted(path: &Path) {
    for (eager, mode) in OPEN_MODES {
        match outcome(path, true, eager) {
            Err(p) => panic!("{} ({mode}): the reader panicked: {p}", path.display()),
            Ok(Err(e)) => panic!("refused ({mode}): {e}"),
            Ok(Ok(())) => {}
        }
    }
}

// ---------------------------------------------------------------------------------------
// Patching bytes in place and recomputing checksums.

fn header(b: &[u8]) -> Header {
    bytemuck::pod_read_unaligned(&b[..64])
}

fn put_header(b: &mut [u8], h: &Header) {
    b[..64].copy_from_slice(bytemuck::bytes_of(h));
}

/// The section table of a file whose table lies where its header says.
fn table(b: &[u8]) -> Vec<SectionEntry> {
    let h = header(b);
    let at = h.section_table_offset as usize;
    records(&b[at..at + 32 * h.section_count as usize])
}

fn put_table(b: &mut [u8], t: &[SectionEntry]) {
    let at = header(b).section_table_offset as usize;
    let bytes: &[u8] = bytemuck::cast_slice(t);
    b[at..at + bytes.len()].copy_from_slice(bytes);
}

fn index_of(t: &[SectionEntry], kind: SectionKind, level: u32) -> usize {
    t.iter()
        .position(|s| s.kind == kind as u32 && s.level == level)
        .unwrap_or_else(|| panic!("fixture has no {} section {level}", kind.name()))
}

/// Recomputes the header checksum.
fn seal_header(b: &mut [u8]) {
    let mut h = header(b);
    h.header_checksum = xxh3_64(&bytemuck::bytes_of(&h)[..56]);
    put_header(b, &h);
}

/// Sets `file_size` to the length and recomputes the table checksum (over the bytes where
/// the header puts the table, when they lie in the file) and the header checksum.
fn seal_table_and_header(b: &mut [u8]) {
    let mut h = header(b);
    h.file_size = b.len() as u64;
    let end = h
        .section_table_offset
        .checked_add(32 * u64::from(h.section_count))
        .filter(|&e| e <= b.len() as u64);
    if let Some(end) = end {
        h.section_table_checksum = xxh3_64(&b[h.section_table_offset as usize..end as usize]);
    }
    put_header(b, &h);
    seal_header(b);
}

/// Recomputes every checksum: each section's that lies inside the file, the table's and
/// the header's; so only the structural checks can object to the file.
fn reseal(b: &mut [u8]) {
    let len = b.len() as u64;
    let mut t = table(b);
    for s in &mut t {
        if let Some(end) = s.offset.checked_add(s.length).filter(|&e| e <= len) {
            s.checksum = xxh3_64(&b[s.offset as usize..end as usize]);
        }
    }
    put_table(b, &t);
    seal_table_and_header(b);
}

/// Writes `bytes` as `dir/name` and returns the path.
fn write(dir: &Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

// ---------------------------------------------------------------------------------------
// Rewriting whole sections through the writer (all checksums right by construction).

struct Doc {
    bits: u32,
    sections: Vec<(SectionKind, u32, Vec<u8>)>,
}

impl Doc {
    fn parse(b: &[u8]) -> Doc {
        let sections = table(b)
            .iter()
            .map(|s| {
                let kind = SectionKind::from_code(s.kind).unwrap();
                let at = s.offset as usize;
                (kind, s.level, b[at..at + s.length as usize].to_vec())
            })
            .collect();
        Doc {
            bits: header(b).position_bits,
            sections,
        }
    }

    fn section(&mut self, kind: SectionKind, level: u32) -> &mut Vec<u8> {
        self.sections
            .iter_mut()
            .find(|(k, l, _)| *k == kind && *l == level)
            .map(|(_, _, b)| b)
            .unwrap_or_else(|| panic!("no {} section {level}", kind.name()))
    }

    fn remove(&mut self, kind: SectionKind, level: u32) {
        self.sections
            .retain(|(k, l, _)| !(*k == kind && *l == level));
    }

    fn levels(&mut self) -> Vec<LevelRecord> {
        records(self.section(SectionKind::Levels, 0))
    }

    fn set_levels(&mut self, v: &[LevelRecord]) {
        *self.section(SectionKind::Levels, 0) = bytemuck::cast_slice(v).to_vec();
    }

    fn nodes(&mut self) -> Vec<NodeRecord> {
        records(self.section(SectionKind::Nodes, 0))
    }

    fn set_nodes(&mut self, v: &[NodeRecord]) {
        *self.section(SectionKind::Nodes, 0) = bytemuck::cast_slice(v).to_vec();
    }

    fn meta(&mut self) -> serde_json::Value {
        serde_json::from_slice(self.section(SectionKind::Metadata, 0)).unwrap()
    }

    fn set_meta(&mut self, v: &serde_json::Value) {
        *self.section(SectionKind::Metadata, 0) = serde_json::to_vec(v).unwrap();
    }

    fn write(&self, dir: &Path, name: &str) -> std::path::PathBuf {
        let path = dir.join(name);
        let mut w = Writer::create(&path, self.bits).unwrap();
        for (kind, level, bytes) in &self.sections {
            w.write_section(*kind, *level, bytes).unwrap();
        }
        w.finish().unwrap();
        path
    }
}

/// Fixed-size records read from unaligned bytes.
fn records<T: bytemuck::Pod>(bytes: &[u8]) -> Vec<T> {
    bytes
        .chunks_exact(std::mem::size_of::<T>())
        .map(bytemuck::pod_read_unaligned)
        .collect()
}

/// Index of point `i` of level `l` in the node table.
fn node_id(levels: &[LevelRecord], l: usize, i: usize) -> usize {
    levels[l].node_first as usize + i
}

// ---------------------------------------------------------------------------------------
// Tests.

#[test]
fn fixtures_are_valid_and_round_trip_through_the_patch_helpers() {
    let dir = tempfile::tempdir().unwrap();
    for params in [params_u16_delta1(), params_u8_delta2()] {
        let b = valid_bytes(params);
        let f = MdlodFile::open(write(dir.path(), "v.mdlod", &b)).unwrap();
        assert!(f.level_count() >= 4, "{} levels", f.level_count());
        // Per-particle radii: the cloud's own sizes, the rest their species'.
        assert_eq!(
            f.radii().map(<[u16]>::len),
            Some(f.particle_count() as usize)
        );
        assert_eq!(f.header().version_minor, 1);
        f.verify().unwrap();
        // Recomputing every checksum of an untouched file changes nothing.
        let mut r = b.clone();
        reseal(&mut r);
        assert_eq!(r, b);
        // Rewriting it section by section through the writer gives the same bytes.
        let p = Doc::parse(&b).write(dir.path(), "rewritten.mdlod");
        assert_eq!(std::fs::read(p).unwrap(), b);
    }
}

/// Flips each byte at `offsets` (XOR 0xFF, then XOR 0x01) and checks each flip is refused
/// with a message naming the file. Returns how many variants were checked.
fn flip_bytes(b: &[u8], dir: &Path, offsets: impl Iterator<Item = usize>) -> usize {
    let path = write(dir, "flip.mdlod", b);
    let mut file = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
    let mut put = |off: usize, v: u8| {
        file.seek(SeekFrom::Start(off as u64)).unwrap();
        file.write_all(&[v]).unwrap();
    };
    let mut failures = Vec::new();
    let mut checked = 0;
    for off in offsets {
        for x in [0xFFu8, 0x01] {
            put(off, b[off] ^ x);
            checked += 1;
            // Checked on open, verified; and checked as read, every accessor used first
            // (nothing on open catches a flip in the node table then).
            for (eager, touch) in [(u64::MAX, false), (1, true)] {
                match outcome(&path, touch, eager) {
                    Err(p) => failures.push(format!("offset {off} ^{x:#04x}: panic: {p}")),
                    Ok(Ok(())) => failures.push(format!("offset {off} ^{x:#04x}: accepted")),
                    Ok(Err(e)) if !e.to_string().contains("flip.mdlod") => failures.push(format!(
                        "offset {off} ^{x:#04x}: message lacks the file: {e}"
                    )),
                    Ok(Err(_)) => {}
                }
            }
        }
        put(off, b[off]);
    }
    assert!(
        failures.is_empty(),
        "{} of {checked} flipped files not refused properly, first ones:\n{}",
        failures.len(),
        failures[..failures.len().min(20)].join("\n")
    );
    checked
}

/// The offsets to flip: every byte of the header, the section table, METADATA, LEVELS
/// and NODES and of the padding between sections; of the per-point sections (POSITIONS,
/// SPECIES, ATTRIBUTE, whose bytes the reader treats alike) the first and last 16 bytes
/// and every `stride`-th byte.
fn offsets_to_flip(b: &[u8], stride: usize) -> Vec<usize> {
    let per_point: Vec<std::ops::Range<usize>> = table(b)
        .iter()
        .filter(|s| {
            [
                SectionKind::Positions,
                SectionKind::Species,
                SectionKind::Attribute,
            ]
            .iter()
            .any(|k| s.kind == *k as u32)
        })
        .map(|s| s.offset as usize..(s.offset + s.length) as usize)
        .collect();
    (0..b.len())
        .filter(|&o| match per_point.iter().find(|r| r.contains(&o)) {
            None => true,
            Some(r) => o < r.start + 16 || o + 16 >= r.end || (o - r.start) % stride == 0,
        })
        .collect()
}

#[test]
fn flipped_bytes_are_detected() {
    let dir = tempfile::tempdir().unwrap();
    // Smaller files than the other tests' (632 particles), so that this takes seconds in
    // the debug profile; `every_flipped_byte_is_detected` does the larger file whole.
    for (params, stride) in [(params_u16_delta1(), 7), (params_u8_delta2(), 7)] {
        let b = valid_bytes_of(6, params);
        let t0 = Instant::now();
        let checked = flip_bytes(&b, dir.path(), offsets_to_flip(&b, stride).into_iter());
        eprintln!(
            "{checked} flipped variants of a {}-byte file refused in {:?}",
            b.len(),
            t0.elapsed()
        );
    }
}

/// Every byte of the file, both flips: about 140 000 variants, a minute in the debug
/// profile (`cargo test -p mdlod-preprocess --test format_hostile -- --ignored`).
#[test]
#[ignore = "slow in the debug profile; flipped_bytes_are_detected samples the same"]
fn every_flipped_byte_is_detected() {
    let dir = tempfile::tempdir().unwrap();
    let b = valid_bytes(params_u16_delta1());
    flip_bytes(&b, dir.path(), 0..b.len());
}

#[test]
fn truncated_or_extended_files_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let b = valid_bytes(params_u16_delta1());
    let mut lengths = vec![0, 1, 7, 8, 63, 64, 65, b.len() - 1];
    for s in table(&b) {
        let (o, l) = (s.offset as usize, s.length as usize);
        lengths.extend([o, o + 1, o + l / 2, o + l - 1, o + l]);
    }
    let table_at = header(&b).section_table_offset as usize;
    lengths.extend([table_at, table_at + 31, table_at + 32]);
    lengths.retain(|&l| l < b.len());
    lengths.sort_unstable();
    lengths.dedup();
    for len in lengths {
        let p = write(dir.path(), &format!("cut-{len}.mdlod"), &b[..len]);
        let msg = expect_refused(&p, &[]);
        if len >= 64 {
            assert!(msg.contains("truncated"), "{msg}");
        } else if len >= 8 {
            assert!(msg.contains("shorter than"), "{msg}");
        }
    }
    let mut longer = b.clone();
    longer.push(0);
    let p = write(dir.path(), "appended.mdlod", &longer);
    expect_refused(&p, &["header", "appended"]);
    let p = write(dir.path(), "not-mdlod.mdlod", b"ITEM: TIMESTEP\n0\n");
    expect_refused(&p, &["not an .mdlod file"]);
    let p = dir.path().join("missing.mdlod");
    expect_refused(&p, &[]);
}

#[test]
fn other_major_versions_are_refused_with_a_hint() {
    let dir = tempfile::tempdir().unwrap();
    let b = valid_bytes(params_u16_delta1());
    let with_version = |major: u16, minor: u16| {
        let mut v = b.clone();
        let mut h = header(&v);
        h.version_major = major;
        h.version_minor = minor;
        put_header(&mut v, &h);
        seal_header(&mut v);
        v
    };
    let p = write(dir.path(), "v2.mdlod", &with_version(2, 0));
    expect_refused(&p, &["version 2.0", "newer", "upgrade", "1 to 1"]);
    let p = write(dir.path(), "v65535.mdlod", &with_version(u16::MAX, 3));
    expect_refused(&p, &["version 65535.3", "newer"]);
    let p = write(dir.path(), "v0.mdlod", &with_version(0, 9));
    expect_refused(&p, &["version 0.9", "convert the source data again"]);
    // A newer minor version only adds; it is read.
    let p = write(dir.path(), "v1.7.mdlod", &with_version(1, 7));
    expect_accepted(&p);
}

#[test]
fn an_unknown_section_kind_is_skipped() {
    // What a later minor version may add: a section of a kind this reader does not know.
    let dir = tempfile::tempdir().unwrap();
    let mut doc = Doc::parse(&valid_bytes(params_u16_delta1()));
    doc.sections
        .insert(2, (SectionKind::Attribute, 77, b"future data".to_vec()));
    let mut b = std::fs::read(doc.write(dir.path(), "tmp.mdlod")).unwrap();
    let mut t = table(&b);
    let i = index_of(&t, SectionKind::Attribute, 77);
    t[i].kind = 99;
    put_table(&mut b, &t);
    reseal(&mut b);
    let p = write(dir.path(), "unknown-kind.mdlod", &b);
    expect_accepted(&p);
    // ... but its checksum is still verified.
    let at = t[i].offset as usize;
    b[at] ^= 1;
    let p = write(dir.path(), "unknown-kind-flipped.mdlod", &b);
    expect_refused(&p, &["section 2 (unknown, level 77)", "checksum"]);
}

#[test]
fn hostile_header_and_section_table() {
    let dir = tempfile::tempdir().unwrap();
    let b = valid_bytes(params_u16_delta1());
    let t = table(&b);
    let file_len = b.len() as u64;
    let table_at = header(&b).section_table_offset;
    let pos2 = index_of(&t, SectionKind::Positions, 2);
    let levels = index_of(&t, SectionKind::Levels, 0);
    let nodes = index_of(&t, SectionKind::Nodes, 0);

    type Patch = Box<dyn Fn(&mut Header, &mut Vec<SectionEntry>)>;
    let cases: Vec<(&str, Patch, Vec<String>)> = vec![
        (
            "offset-plus-length-overflows",
            Box::new(move |_, t| t[pos2].length = u64::MAX - 32),
            vec![
                format!("section {pos2} (POSITIONS, level 2)"),
                "does not fit".into(),
            ],
        ),
        (
            "offset-near-u64-max",
            Box::new(move |_, t| t[pos2].offset = !63u64),
            vec![
                format!("section {pos2} (POSITIONS, level 2)"),
                "does not fit".into(),
            ],
        ),
        (
            "section-beyond-file-end",
            Box::new(move |_, t| t[nodes].offset = (file_len + 64) & !63),
            vec![
                format!("section {nodes} (NODES, level 0)"),
                "does not fit".into(),
            ],
        ),
        (
            "section-over-the-table",
            Box::new(move |_, t| t[levels].offset = table_at),
            vec![format!("section {levels} (LEVELS, level 0)")],
        ),
        (
            "section-in-the-header",
            Box::new(move |_, t| t[levels].offset = 0),
            vec![format!("section {levels} (LEVELS, level 0) at offset 0")],
        ),
        (
            "section-misaligned",
            Box::new(move |_, t| t[nodes].offset += 8),
            vec![format!("section {nodes} (NODES"), "multiple of 64".into()],
        ),
        (
            "sections-overlap",
            Box::new(move |_, t| t[pos2].offset = t[nodes].offset),
            vec!["overlaps section".into()],
        ),
        (
            "duplicate-positions",
            Box::new(move |_, t| t[pos2].level = 1),
            vec!["second POSITIONS section".into()],
        ),
        (
            "duplicate-metadata",
            Box::new(move |_, t| t[levels].kind = SectionKind::Metadata as u32),
            vec!["second METADATA section".into()],
        ),
        (
            "levels-missing",
            Box::new(move |_, t| t[levels].kind = 1000),
            vec!["section table".into(), "no LEVELS section".into()],
        ),
        (
            "positions-level-missing",
            Box::new(move |_, t| t[pos2].level = 200),
            vec!["no POSITIONS section for level 2".into()],
        ),
        (
            "huge-section-count",
            Box::new(|h, _| h.section_count = u32::MAX),
            vec!["header (offset 16)".into(), "4294967295 sections".into()],
        ),
        (
            "section-count-past-file-end",
            Box::new(|h, _| h.section_count = 1 << 16),
            vec!["header (offset 24)".into(), "does not lie inside".into()],
        ),
        (
            "no-sections",
            Box::new(|h, _| h.section_count = 0),
            vec!["no METADATA section".into()],
        ),
        (
            "table-offset-overflows",
            Box::new(|h, _| h.section_table_offset = !63u64),
            vec!["header (offset 24)".into()],
        ),
        (
            "table-in-header",
            Box::new(|h, _| h.section_table_offset = 0),
            vec!["header (offset 24)".into()],
        ),
        (
            "position-bits-12",
            Box::new(|h, _| h.position_bits = 12),
            vec!["header (offset 20)".into(), "position bits 12".into()],
        ),
        (
            "position-bits-disagree",
            Box::new(|h, _| h.position_bits = 8),
            vec!["METADATA".into(), "position_bits 16".into()],
        ),
    ];
    for (name, patch, wants) in cases {
        let mut v = b.clone();
        let mut h = header(&v);
        let mut t = table(&v);
        patch(&mut h, &mut t);
        put_table(&mut v, &t);
        reseal(&mut v);
        // Header fields last: the table stays where the fixture has it.
        let mut sealed = header(&v);
        (
            sealed.section_count,
            sealed.section_table_offset,
            sealed.position_bits,
        ) = (h.section_count, h.section_table_offset, h.position_bits);
        put_header(&mut v, &sealed);
        seal_table_and_header(&mut v);
        let p = write(dir.path(), &format!("{name}.mdlod"), &v);
        let wants: Vec<&str> = wants.iter().map(String::as_str).collect();
        expect_refused(&p, &wants);
    }

    // A stated size that is not the file's.
    let mut v = b.clone();
    let mut h = header(&v);
    h.file_size += 64;
    put_header(&mut v, &h);
    seal_header(&mut v);
    let p = write(dir.path(), "file-size.mdlod", &v);
    expect_refused(&p, &["header", "states a file size"]);

    // A section table at an offset that is not a multiple of 64.
    let mut v = b[..table_at as usize].to_vec();
    v.extend([0u8; 32]);
    v.extend(&b[table_at as usize..]);
    let mut h = header(&v);
    h.section_table_offset += 32;
    put_header(&mut v, &h);
    seal_table_and_header(&mut v);
    let p = write(dir.path(), "table-misaligned.mdlod", &v);
    expect_refused(&p, &["header (offset 24)", "multiple of 64"]);

    // Padding between sections is covered by no checksum but must be zero.
    let s = t
        .iter()
        .find(|s| s.length % 64 != 0)
        .expect("a section that needs padding");
    let pad = (s.offset + s.length) as usize;
    let mut v = b.clone();
    v[pad] = 0x5A;
    let p = write(dir.path(), "padding.mdlod", &v);
    expect_refused(&p, &[&format!("byte {pad}"), "padding"]);
    // So must anything after the table.
    let mut v = b.clone();
    v.extend([0u8, 0, 0, 7]);
    seal_table_and_header(&mut v);
    let p = write(dir.path(), "after-table.mdlod", &v);
    expect_refused(&p, &[&format!("byte {}", b.len() + 3), "padding"]);
}

#[test]
fn hostile_levels() {
    let dir = tempfile::tempdir().unwrap();
    let b = valid_bytes(params_u16_delta1());
    let mut doc = Doc::parse(&b);
    let levels = doc.levels();
    let last = levels.len() - 1;

    type Patch = Box<dyn Fn(&mut Vec<LevelRecord>)>;
    let cases: Vec<(&str, Patch, Vec<String>)> = vec![
        (
            "one-level",
            Box::new(|l| l.truncate(1)),
            vec!["LEVELS".into(), "1 levels (must be 2 to 255)".into()],
        ),
        (
            "no-levels",
            Box::new(|l| l.clear()),
            vec!["LEVELS".into(), "0 levels".into()],
        ),
        (
            "256-levels",
            Box::new(|l| l.resize(256, l[1])),
            vec!["LEVELS".into(), "256 levels".into()],
        ),
        (
            "level-0-with-2-points",
            Box::new(|l| l[0].point_count = 2),
            vec!["level 0".into(), "2 points".into()],
        ),
        (
            "level-2-empty",
            Box::new(|l| l[2].point_count = 0),
            vec!["level 2".into(), "0 points".into()],
        ),
        (
            "level-2-too-many",
            Box::new(|l| l[2].point_count = 1 << 32),
            vec!["level 2".into(), "4294967296 points".into()],
        ),
        (
            "level-3-first-node",
            Box::new(|l| l[3].node_first += 1),
            vec!["level 3".into(), "first node".into()],
        ),
        (
            // Each level within 2^32-1 points, but more nodes in all than u32 numbers.
            "more-nodes-than-32-bits-number",
            Box::new(|l| {
                let extra = u64::from(u32::MAX) - l[1].point_count;
                l[1].point_count = u64::from(u32::MAX);
                for r in &mut l[2..] {
                    r.node_first += extra;
                }
            }),
            vec![format!("level {last}"), "nodes above it".into()],
        ),
        (
            "last-level-more-points",
            Box::new(move |l| l[last].point_count += 1),
            vec!["METADATA".into(), "particles".into()],
        ),
        (
            "level-1-one-point-more",
            Box::new(|l| {
                l[1].point_count += 1;
                for r in &mut l[2..] {
                    r.node_first += 1;
                }
            }),
            vec!["NODES".into(), "expected".into()],
        ),
    ];
    for (name, patch, wants) in cases {
        let mut d = Doc::parse(&b);
        let mut l = levels.clone();
        patch(&mut l);
        d.set_levels(&l);
        let p = d.write(dir.path(), &format!("{name}.mdlod"));
        let wants: Vec<&str> = wants.iter().map(String::as_str).collect();
        expect_refused(&p, &wants);
    }

    let mut d = Doc::parse(&b);
    d.section(SectionKind::Levels, 0).push(0);
    let p = d.write(dir.path(), "levels-33-bytes.mdlod");
    expect_refused(&p, &["LEVELS", "multiple of 32"]);
}

/// A valid file of 2·40³ + 200 particles in clusters of at most 4: its deepest node
/// level spans more than 8 blocks of `NODE_BLOCK` nodes, the one above it three.
fn many_blocks_bytes() -> Vec<u8> {
    valid_bytes_of(
        40,
        BuildParams {
            max_cluster_size: 4,
            max_root_points: 16,
            ..Default::default()
        },
    )
}

/// Levels of many blocks are checked on every core when checked whole
/// (`check_all_nodes`, as `verify` runs it), and the failure reported is that of the
/// lowest corrupt node, whichever core found which.
#[test]
fn lazily_checked_levels_report_their_lowest_corrupt_node() {
    let dir = tempfile::tempdir().unwrap();
    let mut d = Doc::parse(&many_blocks_bytes());
    let levels = d.levels();
    let deepest = levels.len() - 2;
    let first = levels[deepest].node_first as usize;
    let count = levels[deepest].point_count as usize;
    assert!(
        count > 8 * mdlod_format::reader::NODE_BLOCK,
        "{count} nodes"
    );
    let clean = d.nodes();
    let (early, late) = (first + count / 3, first + 5 * count / 6);
    for (corrupt, name, wants) in [
        (vec![early, late], "two-corrupt.mdlod", early),
        (vec![late], "late-corrupt.mdlod", late),
    ] {
        let mut nodes = clean.clone();
        for &id in &corrupt {
            nodes[id].bounds_min[0] = nodes[id].bounds_max[0] + 1.0;
        }
        d.set_nodes(&nodes);
        let p = d.write(dir.path(), name);
        let f = MdlodFile::open_with_eager_nodes(&p, 1).unwrap();
        let msg = f.check_all_nodes().unwrap_err().to_string();
        assert!(
            msg.contains(name) && msg.contains(&format!("node {wants}:")),
            "{msg}"
        );
        assert!(f.node_error().is_err());
        let eager = MdlodFile::open(&p).err().unwrap().to_string();
        assert!(eager.contains(&format!("node {wants}:")), "{eager}");
    }
}

/// Blocks of a lazily checked level are checked in whatever order they are asked for,
/// each reporting its own corrupt node, first or last in the block; a block that is
/// never asked for is never read, and a checked node cannot claim node children that
/// belong to another checked node, whatever lies between them.
#[test]
fn lazily_checked_blocks_stand_on_their_own() {
    use mdlod_format::reader::NODE_BLOCK;
    let dir = tempfile::tempdir().unwrap();
    let mut d = Doc::parse(&many_blocks_bytes());
    let levels = d.levels();
    let clean = d.nodes();
    let open = |d: &Doc, name: &str| {
        let p = d.write(dir.path(), name);
        MdlodFile::open_with_eager_nodes(&p, 1).unwrap()
    };
    // A level whose children are nodes, of at least three blocks.
    let l = (1..levels.len() - 2)
        .find(|&l| levels[l].point_count as usize > 2 * NODE_BLOCK)
        .expect("a level of three blocks");
    let first = levels[l].node_first as usize;
    let count = levels[l].point_count as usize;
    let blocks = count.div_ceil(NODE_BLOCK);

    // The clean file, blocks asked for last first.
    let f = open(&d, "clean.mdlod");
    for b in (0..blocks).rev() {
        f.check_nodes(l, b * NODE_BLOCK..((b + 1) * NODE_BLOCK).min(count))
            .unwrap();
    }
    assert!(f.node_error().is_ok());

    // The first node of block 1 and the last of block 0 broken: each block names its own.
    for (id, name) in [
        (first + NODE_BLOCK, "block-first.mdlod"),
        (first + NODE_BLOCK - 1, "block-last.mdlod"),
    ] {
        let mut nodes = clean.clone();
        nodes[id].radius = -1.0;
        d.set_nodes(&nodes);
        let f = open(&d, name);
        let other = if id == first + NODE_BLOCK { 0 } else { 1 };
        f.check_nodes(l, other * NODE_BLOCK..(other + 1) * NODE_BLOCK)
            .unwrap();
        let msg = f
            .check_nodes(l, id - first..id - first + 1)
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains(name) && msg.contains(&format!("node {id}:")),
            "{msg}"
        );
        // Asked again, the failed block fails again, with the same message.
        let again = f.check_nodes(l, id - first..id - first + 1).unwrap_err();
        assert_eq!(again.to_string(), msg);
    }

    // Two checked nodes claiming the same node children across a block never checked:
    // block 0's last node and block 2's first both claim everything from the former's
    // first child to the latter's last, every one of those children names the former
    // as its parent, and block 1's last node ends where block 2's first starts (block 1
    // is broken: its other nodes no longer meet its last).
    let (p0, x, p1) = (
        first + NODE_BLOCK - 1,
        first + 2 * NODE_BLOCK,
        first + 2 * NODE_BLOCK - 1,
    );
    let mut nodes = clean.clone();
    let (a, z) = (
        nodes[p0].child_first,
        nodes[x].child_first + nodes[x].child_count,
    );
    for id in [p0, x] {
        nodes[id].child_first = a;
        nodes[id].child_count = z - a;
    }
    nodes[p1].child_first = a - 1;
    nodes[p1].child_count = 1;
    let below = levels[l + 1].node_first as usize;
    for c in a..z {
        nodes[below + c as usize].parent = p0 as u32;
    }
    d.set_nodes(&nodes);
    let f = open(&d, "overlap.mdlod");
    f.check_nodes(l, 0..NODE_BLOCK).unwrap();
    f.check_nodes(l, 2 * NODE_BLOCK..2 * NODE_BLOCK + 1)
        .unwrap();
    f.check_children(p0).unwrap();
    let msg = f.check_children(x).unwrap_err().to_string();
    assert!(
        msg.contains("overlap.mdlod")
            && msg.contains(&format!("node {}:", below + a as usize))
            && msg.contains(&format!(
                "claimed as a child by node {x} and by its parent {p0}"
            )),
        "{msg}"
    );
    assert!(f.check_all_nodes().is_err());

    // The same claims, the shared children's first and last naming block 2's node and
    // those between naming block 0's: their parents out of order.
    nodes[below + a as usize].parent = x as u32;
    nodes[below + z as usize - 1].parent = x as u32;
    d.set_nodes(&nodes);
    let f = open(&d, "interleaved.mdlod");
    let msg = f.check_children(x).unwrap_err().to_string();
    assert!(
        msg.contains("interleaved.mdlod")
            && msg.contains(&format!("node {}:", below + a as usize + 1))
            && msg.contains(&format!(
                "parent {p0} comes before its predecessor's parent {x} (node {}'s record, or \
                 this one's, is damaged)",
                below + a as usize
            )),
        "{msg}"
    );
}

#[test]
fn hostile_nodes() {
    let dir = tempfile::tempdir().unwrap();
    let b = valid_bytes(params_u16_delta1());
    let mut doc = Doc::parse(&b);
    let lv = doc.levels();
    let nodes = doc.nodes();
    let last = lv.len() - 1;
    let count = |l: usize| lv[l].point_count as usize;
    assert!(count(1) >= 3 && last >= 4);
    let l1_last = node_id(&lv, 1, count(1) - 1);
    let l1_second = node_id(&lv, 1, 1);
    let l2_first = node_id(&lv, 2, 0);
    // The last node of a level whose last node has several children.
    let (gap_level, gap_node) = (0..last)
        .map(|l| (l, node_id(&lv, l, count(l) - 1)))
        .find(|&(_, id)| nodes[id].child_count >= 2)
        .unwrap();
    // A level-2 node whose parent is not the last level-1 node.
    let l2_other = (0..count(2))
        .map(|i| node_id(&lv, 2, i))
        .find(|&id| (nodes[id].parent as usize) < l1_last)
        .unwrap();
    let l2_other_parent = nodes[l2_other].parent as usize;
    // A level-1 node drawn with several points.
    let l1_multi = (0..count(1))
        .map(|i| node_id(&lv, 1, i))
        .find(|&id| nodes[id].point_count >= 2)
        .unwrap();

    type Patch = Box<dyn Fn(&mut Vec<NodeRecord>)>;
    let id = |i: usize| format!("node {i}:");
    let cases: Vec<(&str, Patch, Vec<String>)> = vec![
        (
            "child-range-past-next-level",
            Box::new(move |n| n[l1_last].child_count += 1),
            vec![id(l1_last), "beyond the".into()],
        ),
        (
            "child-range-huge",
            Box::new(move |n| n[l1_last].child_count = u32::MAX),
            vec![id(l1_last), "beyond the".into()],
        ),
        (
            "child-ranges-leave-a-hole",
            Box::new(move |n| n[l1_second].child_first += 1),
            vec![id(l1_second), "do not continue".into()],
        ),
        (
            "child-ranges-overlap",
            Box::new(move |n| n[l1_second].child_first -= 1),
            vec![id(l1_second), "do not continue".into()],
        ),
        (
            "no-children",
            Box::new(move |n| n[l1_second].child_count = 0),
            vec![id(l1_second), "count ≥ 1".into()],
        ),
        (
            "children-fall-short-of-next-level",
            Box::new(move |n| n[gap_node].child_count -= 1),
            vec![format!("level {gap_level}:"), "children but level".into()],
        ),
        (
            "parent-is-itself",
            Box::new(move |n| n[l2_first].parent = l2_first as u32),
            vec![id(l2_first), "parent".into()],
        ),
        (
            "parent-missing",
            Box::new(move |n| n[l2_first].parent = u32::MAX),
            vec![id(l2_first), "parent 4294967295".into()],
        ),
        (
            "parent-on-wrong-level",
            Box::new(move |n| n[l2_first].parent = 0),
            vec![id(l2_first), "parent 0".into()],
        ),
        (
            "parent-not-listing-it",
            Box::new(move |n| n[l2_other].parent = l2_other_parent as u32 + 1),
            vec![id(l2_other), "does not list it".into()],
        ),
        (
            "top-node-with-parent",
            Box::new(|n| n[0].parent = 1),
            vec![id(0), "top node has a parent".into()],
        ),
        (
            "wrong-level-byte",
            Box::new(move |n| n[l2_first].level = 7),
            vec![id(l2_first), "level 7".into()],
        ),
        (
            "wrong-point-level",
            Box::new(move |n| n[l2_first].point_level = 200),
            vec![id(l2_first), "point level 200".into()],
        ),
        (
            "point-range-outside-level",
            Box::new(move |n| n[l2_first].point_first = u32::MAX - 1),
            vec![id(l2_first), "outside the".into()],
        ),
        (
            "point-range-empty",
            Box::new(move |n| n[l2_first].point_count = 0),
            vec![id(l2_first), "outside the".into()],
        ),
        (
            "point-range-not-the-descendants",
            Box::new(move |n| {
                n[l1_multi].point_first += 1;
                n[l1_multi].point_count -= 1;
            }),
            vec![id(l1_multi), "descendants".into()],
        ),
        (
            "encoding-node-wrong",
            Box::new(move |n| n[l2_first].quant_node = 0),
            vec![id(l2_first), "encoding node 0".into()],
        ),
        (
            "nan-centroid",
            Box::new(move |n| n[l1_second].centroid[1] = f32::NAN),
            vec![id(l1_second), "centroid.y is NaN (must be finite)".into()],
        ),
        (
            "infinite-radius",
            Box::new(move |n| n[l2_first].radius = f32::INFINITY),
            vec![id(l2_first), "radius is inf (must be finite)".into()],
        ),
        (
            "negative-quant-scale",
            Box::new(move |n| n[l2_first].quant_scale[2] = -1.0),
            vec![
                id(l2_first),
                "quant_scale.z is -1e0 (must not be negative)".into(),
            ],
        ),
        (
            "nan-bounds",
            Box::new(move |n| n[0].bounds_max[0] = f32::NAN),
            vec![id(0), "bounds_max.x is NaN (must be finite)".into()],
        ),
        (
            "inverted-bounds",
            Box::new(move |n| n[l2_first].bounds_min[0] = n[l2_first].bounds_max[0] + 1.0),
            vec![id(l2_first), "bounds_min exceeds".into()],
        ),
        (
            "species-out-of-range",
            Box::new(move |n| n[l2_first].species = 2),
            vec![id(l2_first), "species 2 of 2".into()],
        ),
        (
            "huge-quant-scale",
            Box::new(move |n| n[l1_second].quant_scale = [3e38; 3]),
            vec![
                id(l1_second),
                "quantization scale 3e38 on axis 0 spreads its points past".into(),
            ],
        ),
        (
            // A box narrower than its children's (each within the file's other rules):
            // a renderer would cull particles by it, so `verify` refuses it.
            "bounds-narrower-than-children",
            Box::new(move |n| {
                let c = n[l1_second].centroid;
                for k in 0..3 {
                    let (lo, hi) = (n[l1_second].bounds_min[k], n[l1_second].bounds_max[k]);
                    n[l1_second].bounds_min[k] = c[k] - 0.6 * (c[k] - lo);
                    n[l1_second].bounds_max[k] = c[k] + 0.6 * (hi - c[k]);
                }
            }),
            vec![
                "its bounds reach".into(),
                format!("past those of its parent node {l1_second} on level 1"),
            ],
        ),
        (
            "centroid-moved-away",
            Box::new(move |n| n[l1_second].centroid[0] += 1000.0),
            vec![
                "level 2, point".into(),
                "decodes to [".into(),
                format!("outside the bounds of its parent node {l1_second} on level 1"),
            ],
        ),
    ];
    for (name, patch, wants) in cases {
        let mut d = Doc::parse(&b);
        let mut n = nodes.clone();
        patch(&mut n);
        d.set_nodes(&n);
        let p = d.write(dir.path(), &format!("{name}.mdlod"));
        let wants: Vec<&str> = wants.iter().map(String::as_str).collect();
        expect_refused(&p, &wants);
    }

    let mut d = Doc::parse(&b);
    d.section(SectionKind::Nodes, 0)
        .truncate(nodes.len() * 96 - 96);
    let p = d.write(dir.path(), "one-node-short.mdlod");
    expect_refused(&p, &["NODES", "expected"]);
}

#[test]
fn hostile_per_particle_sections() {
    let dir = tempfile::tempdir().unwrap();
    let b = valid_bytes(params_u16_delta1());
    let last = Doc::parse(&b).levels().len() as u32 - 1;

    type Patch = Box<dyn Fn(&mut Doc)>;
    let cases: Vec<(&str, Patch, Vec<String>)> = vec![
        (
            "positions-one-point-short",
            Box::new(|d| {
                let p = d.section(SectionKind::Positions, 2);
                p.truncate(p.len() - 6);
            }),
            vec!["POSITIONS, level 2".into(), "expected".into()],
        ),
        (
            "positions-odd-length",
            Box::new(|d| d.section(SectionKind::Positions, 1).push(0)),
            vec!["POSITIONS, level 1".into(), "expected".into()],
        ),
        (
            "positions-missing",
            Box::new(move |d| d.remove(SectionKind::Positions, last)),
            vec![format!("no POSITIONS section for level {last}")],
        ),
        (
            "species-too-long",
            Box::new(move |d| d.section(SectionKind::Species, last).extend([0, 0])),
            vec!["SPECIES".into(), "species indices".into()],
        ),
        (
            "species-missing",
            Box::new(move |d| d.remove(SectionKind::Species, last)),
            vec!["no SPECIES section".into()],
        ),
        (
            "species-index-out-of-range",
            Box::new(move |d| {
                d.section(SectionKind::Species, last)[10..12].copy_from_slice(&2u16.to_le_bytes())
            }),
            vec!["SPECIES, particle 5".into(), "species index 2".into()],
        ),
        (
            "species-index-max",
            Box::new(move |d| {
                let s = d.section(SectionKind::Species, last);
                let n = s.len();
                s[n - 2..].copy_from_slice(&[0xFF, 0xFF]);
            }),
            vec!["SPECIES, particle".into(), "species index 65535".into()],
        ),
        (
            "attribute-without-metadata",
            Box::new(|d| {
                let mut m = d.meta();
                m.as_object_mut().unwrap().remove("attribute");
                d.set_meta(&m);
            }),
            vec!["METADATA".into(), "ATTRIBUTE section is present".into()],
        ),
        (
            "metadata-attribute-without-section",
            Box::new(move |d| d.remove(SectionKind::Attribute, last)),
            vec!["no ATTRIBUTE section".into()],
        ),
        (
            "attribute-wrong-length",
            Box::new(move |d| d.section(SectionKind::Attribute, last).truncate(10)),
            vec!["ATTRIBUTE".into(), "expected".into()],
        ),
        (
            "radius-without-metadata",
            Box::new(|d| {
                let mut m = d.meta();
                m.as_object_mut().unwrap().remove("radius");
                d.set_meta(&m);
            }),
            vec!["METADATA".into(), "RADIUS section is present".into()],
        ),
        (
            "metadata-radius-without-section",
            Box::new(move |d| d.remove(SectionKind::Radius, last)),
            vec!["no RADIUS section".into()],
        ),
        (
            "radius-wrong-length",
            Box::new(move |d| d.section(SectionKind::Radius, last).extend([0, 0])),
            vec!["RADIUS".into(), "expected".into(), "u16 radii".into()],
        ),
        (
            "radius-range-reversed",
            Box::new(|d| {
                let mut m = d.meta();
                m["radius"] = serde_json::json!({ "min": 2.0, "max": 1.0 });
                d.set_meta(&m);
            }),
            vec!["METADATA".into(), "radius range 2 to 1".into()],
        ),
        (
            // The `Cu` particles (species 0, of one size, 1.28) at the range's start (1):
            // smaller spheres, still inside their bounds, but outside their species'
            // sizes.
            "radius-outside-species-sizes",
            Box::new(move |d| {
                let species = d.section(SectionKind::Species, last).clone();
                let r = d.section(SectionKind::Radius, last);
                for (q, s) in r.chunks_exact_mut(2).zip(species.chunks_exact(2)) {
                    if s == [0, 0] {
                        q.copy_from_slice(&[0, 0]);
                    }
                }
            }),
            vec![
                "RADIUS, particle".into(),
                "outside its species' sizes 1.28".into(),
            ],
        ),
        (
            // The range and the cloud species' sizes stretched to 10^8, which the
            // particles at the range's end now take: within their species' sizes, but
            // spheres far wider than the bounds built for them.
            "radius-wider-than-bounds",
            Box::new(move |d| {
                let mut m = d.meta();
                m["radius"]["max"] = serde_json::json!(1e8);
                m["species"][1]["radius_range"][1] = serde_json::json!(1e8);
                d.set_meta(&m);
            }),
            vec!["wider than its parent node's bounds".into()],
        ),
        (
            // A list of the object's values, which serde alone would take.
            "radius-range-a-list",
            Box::new(|d| {
                let mut m = d.meta();
                m["radius"] = serde_json::json!([1.0, 2.0]);
                d.set_meta(&m);
            }),
            vec!["METADATA".into(), "`radius` is not an object".into()],
        ),
        (
            "attribute-a-list",
            Box::new(|d| {
                let mut m = d.meta();
                m["attribute"] = serde_json::json!(["c_pe", -1.0, 1.0]);
                d.set_meta(&m);
            }),
            vec!["METADATA".into(), "`attribute` is not an object".into()],
        ),
        (
            "radius-range-negative",
            Box::new(|d| {
                let mut m = d.meta();
                m["radius"] = serde_json::json!({ "min": -1.0, "max": 1.0 });
                d.set_meta(&m);
            }),
            vec!["METADATA".into(), "radius range -1 to 1".into()],
        ),
    ];
    for (name, patch, wants) in cases {
        let mut d = Doc::parse(&b);
        patch(&mut d);
        let p = d.write(dir.path(), &format!("{name}.mdlod"));
        let wants: Vec<&str> = wants.iter().map(String::as_str).collect();
        expect_refused(&p, &wants);
    }
}

#[test]
fn a_radius_section_under_a_version_1_0_header_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mut b = valid_bytes(params_u16_delta1());
    let mut h = header(&b);
    assert_eq!((h.version_major, h.version_minor), (1, 1));
    h.version_minor = 0;
    put_header(&mut b, &h);
    seal_header(&mut b);
    let p = write(dir.path(), "radius-in-1-0.mdlod", &b);
    expect_refused(&p, &["header", "version 1.0 holds a RADIUS section"]);
}

/// Radii on a log scale (RADIUS_LOG, metadata `radius_log`, version 1.2) are checked as
/// linear ones are: the section and the field go together, the range starts above 0, and
/// a header of an earlier minor version holding them is refused.
#[test]
fn radii_on_a_log_scale_are_checked_as_linear_ones() {
    let dir = tempfile::tempdir().unwrap();
    let mut frame = test_frame(10);
    // The cloud's Ag from 10^-3 to 10: four decades, a log scale.
    let radii = frame.radii.as_mut().unwrap();
    let k = radii.len() - 200;
    for (i, r) in radii[k..].iter_mut().enumerate() {
        *r = 1e-3 * 10f32.powf(4.0 * i as f32 / 199.0);
    }
    frame.species[1].radius_range = Some((1e-3, 10.0));
    let path = dir.path().join("log.mdlod");
    let opts = ConvertOptions {
        build: params_u16_delta1(),
        ..Default::default()
    };
    convert_frame(&frame, None, &path, &opts, &NoProgress).unwrap();
    let b = std::fs::read(&path).unwrap();
    expect_accepted(&path);
    let h = header(&b);
    assert_eq!((h.version_major, h.version_minor), (1, 2));
    let f = MdlodFile::open(&path).unwrap();
    assert!(f.metadata().radius.unwrap().log);
    assert_eq!(f.radii().unwrap().len(), frame.positions.len());

    let mut older = b.clone();
    let mut h = header(&older);
    h.version_minor = 1;
    put_header(&mut older, &h);
    seal_header(&mut older);
    let p = write(dir.path(), "log-in-1-1.mdlod", &older);
    expect_refused(
        &p,
        &[
            "header",
            "version 1.1 holds a RADIUS_LOG section, which version 1.2 added",
        ],
    );
    let with = |name: &str, f: &dyn Fn(&mut Doc, &mut serde_json::Value)| {
        let mut d = Doc::parse(&b);
        let mut m = d.meta();
        f(&mut d, &mut m);
        d.set_meta(&m);
        d.write(dir.path(), name)
    };
    let p = with("log-listed.mdlod", &|_, m| {
        m["radius_log"] = serde_json::json!([0.001, 10.0])
    });
    expect_refused(&p, &["`radius_log` is not an object"]);
    let p = with("log-from-0.mdlod", &|_, m| {
        m["radius_log"]["min"] = 0.0.into()
    });
    expect_refused(&p, &["METADATA", "radius_log range 0 to 10", "above 0"]);
    let p = with("both-scales.mdlod", &|_, m| {
        m["radius"] = m["radius_log"].clone()
    });
    expect_refused(&p, &["METADATA", "both `radius` and `radius_log`"]);
    // The section of one scale under the field of the other.
    let p = with("log-section-linear-field.mdlod", &|_, m| {
        let r = m.as_object_mut().unwrap().remove("radius_log").unwrap();
        m["radius"] = r;
    });
    expect_refused(&p, &["there is no RADIUS section"]);
    let p = with("linear-section-log-field.mdlod", &|d, _| {
        for s in &mut d.sections {
            if s.0 == SectionKind::RadiusLog {
                s.0 = SectionKind::Radius;
            }
        }
    });
    expect_refused(&p, &["there is no RADIUS_LOG section"]);
    // A radius outside its species' sizes is named in the section that holds it.
    let last = Doc::parse(&b).levels().len() as u32 - 1;
    let p = with("log-radius-outside.mdlod", &|d, _| {
        let species = d.section(SectionKind::Species, last).clone();
        let r = d.section(SectionKind::RadiusLog, last);
        for (q, s) in r.chunks_exact_mut(2).zip(species.chunks_exact(2)) {
            if s == [0, 0] {
                q.copy_from_slice(&[0xff, 0xff]);
            }
        }
    });
    expect_refused(&p, &["RADIUS_LOG, particle", "outside its species' sizes"]);
}

/// Further attributes (ATTRIBUTES, NODE_ATTRIBUTES, metadata `attributes`, version
/// 1.2): sections and field go together at the lengths they give, names are distinct and
/// follow a first attribute, ranges are ranges, means are finite, and an earlier minor
/// version holding them is refused.
#[test]
fn further_attributes_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    let frame = test_frame(10);
    let copy = Attribute {
        name: "c_ke".into(),
        values: frame.positions.iter().map(|p| p[2]).collect(),
    };
    let path = dir.path().join("attrs.mdlod");
    let opts = ConvertOptions {
        build: params_u16_delta1(),
        ..Default::default()
    };
    mdlod_preprocess::convert::convert_frame_with(&frame, &[copy], None, &path, &opts, &NoProgress)
        .unwrap();
    expect_accepted(&path);
    let b = std::fs::read(&path).unwrap();
    let f = MdlodFile::open(&path).unwrap();
    assert_eq!(f.attribute_names(), ["c_pe", "c_ke"]);
    let e = MdlodFile::open(&path)
        .unwrap()
        .select_attribute("c_kE")
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("no attribute named \"c_kE\" (the file keeps c_pe, c_ke"),
        "{e}"
    );

    let mut older = b.clone();
    let mut h = header(&older);
    h.version_minor = 1;
    put_header(&mut older, &h);
    seal_header(&mut older);
    let p = write(dir.path(), "attrs-in-1-1.mdlod", &older);
    expect_refused(
        &p,
        &["version 1.1 holds an ATTRIBUTES section, which version 1.2 added"],
    );
    let with = |name: &str, f: &dyn Fn(&mut Doc, &mut serde_json::Value)| {
        let mut d = Doc::parse(&b);
        let mut m = d.meta();
        f(&mut d, &mut m);
        d.set_meta(&m);
        d.write(dir.path(), name)
    };
    let p = with("no-field.mdlod", &|_, m| {
        m.as_object_mut().unwrap().remove("attributes");
    });
    expect_refused(
        &p,
        &[
            "METADATA",
            "ATTRIBUTES",
            "the metadata lists no `attributes`",
        ],
    );
    let p = with("no-means.mdlod", &|d, _| {
        d.remove(SectionKind::NodeAttributes, 0)
    });
    expect_refused(
        &p,
        &["lists 1 `attributes` but there is no NODE_ATTRIBUTES section"],
    );
    let last = f.level_count() as u32 - 1;
    let p = with("short.mdlod", &|d, _| {
        d.section(SectionKind::Attributes, last).truncate(2);
    });
    expect_refused(&p, &["ATTRIBUTES", "expected 1 attributes of"]);
    // Objects are objects: an entry as a list of its values is refused; null is none.
    let p = with("listed.mdlod", &|_, m| {
        m["attributes"][0] = serde_json::json!(["c_ke", 0.0, 1.0])
    });
    expect_refused(&p, &["attributes[0] is not an object"]);
    let p = with("null.mdlod", &|d, m| {
        m["attributes"] = serde_json::Value::Null;
        d.remove(SectionKind::Attributes, last);
        d.remove(SectionKind::NodeAttributes, 0);
    });
    expect_accepted(&p);
    let p = with("twice.mdlod", &|_, m| {
        m["attributes"][0]["name"] = "c_pe".into()
    });
    expect_refused(&p, &["attributes[0] \"c_pe\": a name given twice"]);
    let p = with("reversed.mdlod", &|_, m| {
        m["attributes"][0]["min"] = 5.0.into();
        m["attributes"][0]["max"] = 1.0.into();
    });
    expect_refused(&p, &["attributes[0] \"c_ke\": range 5 to 1"]);
    let p = with("no-first.mdlod", &|d, m| {
        m.as_object_mut().unwrap().remove("attribute");
        d.remove(SectionKind::Attribute, last);
    });
    expect_refused(&p, &["an extra attribute without a first"]);
    // `log10` belongs to the further attributes' entries: the first's is said by
    // `attribute_log10`. A further one's is taken, and moves there when selected.
    let p = with("first-log10.mdlod", &|_, m| {
        m["attribute"]["log10"] = true.into()
    });
    expect_refused(&p, &["attribute \"c_pe\": `log10` is set in `attribute`"]);
    let p = with("extra-log10.mdlod", &|_, m| {
        m["attributes"][0]["log10"] = true.into()
    });
    expect_accepted(&p);
    let picked = MdlodFile::open(&p)
        .unwrap()
        .select_attribute("c_ke")
        .unwrap();
    assert!(picked.metadata().attribute_log10);
    assert!(!picked.metadata().attribute.as_ref().unwrap().log10);
    // Optional flags given as `null` are absent (section 7), `false` in `attribute` too.
    let p = with("null-flags.mdlod", &|_, m| {
        m["attribute_log10"] = serde_json::Value::Null;
        m["attributes"][0]["log10"] = serde_json::Value::Null;
        m["attribute"]["log10"] = false.into();
    });
    expect_accepted(&p);
    let f = MdlodFile::open(&p).unwrap();
    assert!(!f.metadata().attribute_log10 && !f.metadata().attributes[0].log10);
    let p = with("nan-mean.mdlod", &|d, _| {
        d.section(SectionKind::NodeAttributes, 0)[..4].copy_from_slice(&f32::NAN.to_le_bytes());
    });
    expect_refused(&p, &["NODE_ATTRIBUTES, attribute \"c_ke\", node 0"]);
    let e = MdlodFile::open(&p)
        .unwrap()
        .select_attribute("c_ke")
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("node 0") && e.contains("not finite"), "{e}");
}

#[test]
fn a_position_error_the_particles_exceed_is_refused() {
    // `verify` puts each decoded particle centre inside its cluster's bounds shrunk by
    // its radius, up to the recorded position error: a file claiming a tenth of its
    // real error, or a negative one, is refused. (8-bit positions: the error is far
    // above the bounds' rounding.)
    let dir = tempfile::tempdir().unwrap();
    let b = valid_bytes(params_u8_delta2());
    let recorded = Doc::parse(&b).meta()["max_position_error"]
        .as_f64()
        .unwrap();
    assert!(recorded > 1e-3, "{recorded}");
    let with = |name: &str, error: f64| {
        let mut d = Doc::parse(&b);
        let mut m = d.meta();
        m["max_position_error"] = error.into();
        d.set_meta(&m);
        d.write(dir.path(), name)
    };
    expect_accepted(&with("as-recorded.mdlod", recorded));
    let f = MdlodFile::open(with("as-recorded.mdlod", recorded)).unwrap();
    let seen = f.verify().unwrap().max_particle_error_seen;
    assert!(
        seen > recorded / 5.0 && seen <= recorded * 1.001,
        "{seen} against {recorded}"
    );
    expect_refused(
        &with("understated.mdlod", recorded / 10.0),
        &[
            "particle",
            "beyond where its parent node's bounds put its centre",
        ],
    );
    expect_refused(
        &with("negative.mdlod", -recorded),
        &["maximum position error", "not a finite non-negative number"],
    );
}

#[test]
fn hostile_metadata() {
    let dir = tempfile::tempdir().unwrap();
    let b = valid_bytes(params_u16_delta1());
    let particles = Doc::parse(&b).meta()["particles"].as_u64().unwrap();

    let with = |name: &str, f: &dyn Fn(&mut serde_json::Value)| {
        let mut d = Doc::parse(&b);
        let mut m = d.meta();
        f(&mut m);
        d.set_meta(&m);
        d.write(dir.path(), name)
    };
    let p = with("particles.mdlod", &|m| {
        m["particles"] = (particles + 1).into()
    });
    expect_refused(
        &p,
        &[
            "METADATA",
            &format!("says {} particles", particles + 1),
            &format!("holds {particles}"),
        ],
    );
    let p = with("delta-0.mdlod", &|m| m["build"]["delta_n"] = 0.into());
    expect_refused(&p, &["METADATA", "delta_n 0"]);
    let p = with("delta-99.mdlod", &|m| m["build"]["delta_n"] = 99.into());
    expect_refused(&p, &["METADATA", "delta_n 99"]);
    let p = with("bits-8.mdlod", &|m| m["build"]["position_bits"] = 8.into());
    expect_refused(&p, &["METADATA", "disagrees"]);
    let p = with("no-species.mdlod", &|m| {
        m["species"] = serde_json::json!([])
    });
    expect_refused(&p, &["METADATA", "0 species"]);
    // A polydisperse species' radius range: two positive numbers, the smaller first.
    for (name, range) in [
        ("range-reversed.mdlod", serde_json::json!([2.0, 1.0])),
        ("range-zero.mdlod", serde_json::json!([0.0, 1.0])),
    ] {
        let p = with(name, &|m| m["species"][0]["radius_range"] = range.clone());
        expect_refused(&p, &["METADATA", "radius_range"]);
    }
    let p = with("range-ok.mdlod", &|m| {
        m["species"][0]["radius_range"] = serde_json::json!([0.5, 1.5])
    });
    let f = MdlodFile::open(&p).unwrap();
    assert_eq!(f.metadata().species[0].radius_range, Some([0.5, 1.5]));
    // A species radius past single precision (infinite once read), 0 or negative would
    // draw kernels and splats of any size (a density render ran for minutes); a colour
    // outside 0..1 or an attribute range reversed or past single precision: refused on
    // open, so verify, info and render all say so.
    for (name, field, value, says) in [
        (
            "radius-inf.mdlod",
            "radius",
            serde_json::json!(1e300),
            "radius inf",
        ),
        (
            "radius-0.mdlod",
            "radius",
            serde_json::json!(0.0),
            "radius 0",
        ),
        (
            "radius-neg.mdlod",
            "radius",
            serde_json::json!(-1.0),
            "radius -1",
        ),
        (
            "colour.mdlod",
            "colour",
            serde_json::json!([1e30, -5.0, 2.0]),
            "must be three numbers from 0 to 1",
        ),
    ] {
        let p = with(name, &|m| m["species"][0][field] = value.clone());
        expect_refused(&p, &["METADATA", says]);
    }
    for (name, range, says) in [
        ("attribute-reversed.mdlod", [2.0, 1.0], "range 2 to 1"),
        ("attribute-huge.mdlod", [-1e39, 1.0], "range -inf to 1"),
    ] {
        let p =
            with(
                name,
                &|m| {
                    m["attribute"] =
                        serde_json::json!({"name": "c_pe", "min": range[0], "max": range[1]})
                },
            );
        expect_refused(&p, &["METADATA", "attribute \"c_pe\"", says]);
    }
    let p = with("no-build.mdlod", &|m| {
        m.as_object_mut().unwrap().remove("build");
    });
    expect_refused(&p, &["METADATA section: invalid JSON", "build"]);
    let p = with("particles-negative.mdlod", &|m| {
        m["particles"] = (-1).into()
    });
    expect_refused(&p, &["METADATA section: invalid JSON"]);
    // An optional field may be null: `source.frame` null is frame 0, as absent is.
    let source = serde_json::json!({"path": "d.lammpstrj", "size": 10, "frame": null});
    let p = with("frame-null.mdlod", &|m| m["source"] = source.clone());
    assert_eq!(
        MdlodFile::open(&p)
            .unwrap()
            .metadata()
            .source
            .as_ref()
            .unwrap()
            .frame,
        0
    );
    // A frame's checksum is 16 lowercase hexadecimal digits.
    for (name, xxh3) in [
        ("xxh3-upper.mdlod", "ABCDEF0123456789"),
        ("xxh3-short.mdlod", "abc"),
    ] {
        let source = serde_json::json!({"path": "d.lammpstrj", "size": 10,
            "bytes": {"start": 0, "end": 10, "xxh3": xxh3}});
        let p = with(name, &|m| m["source"] = source.clone());
        expect_refused(
            &p,
            &["METADATA", "not 16 lowercase hexadecimal digits", xxh3],
        );
    }
    let source = serde_json::json!({"path": "d.lammpstrj", "size": 10,
        "bytes": {"start": 0, "end": 10, "xxh3": "0123456789abcdef"}});
    expect_accepted(&with("xxh3-ok.mdlod", &|m| m["source"] = source.clone()));

    let raw = |name: &str, bytes: &[u8]| {
        let mut d = Doc::parse(&b);
        *d.section(SectionKind::Metadata, 0) = bytes.to_vec();
        d.write(dir.path(), name)
    };
    let p = raw("not-json.mdlod", b"particles: 3\n");
    expect_refused(&p, &["METADATA section: invalid JSON"]);
    let p = raw("empty-json.mdlod", b"");
    expect_refused(&p, &["METADATA section: invalid JSON"]);
    let p = raw("json-array.mdlod", b" [1, 2, 3]");
    expect_refused(
        &p,
        &[
            "METADATA",
            "a JSON array where the format has one JSON object",
        ],
    );
    let p = raw("not-utf8.mdlod", b"{\"writer\": \"\xff\xfe\"}");
    expect_refused(&p, &["METADATA", "not UTF-8 text (byte 12 of the section)"]);
    let deep = format!("{}{}", "[".repeat(100_000), "]".repeat(100_000));
    let p = raw("deep-json.mdlod", deep.as_bytes());
    expect_refused(&p, &["METADATA", "a JSON array"]);
    let deep = format!("{}{}", "{\"a\":".repeat(100_000), "}".repeat(100_000));
    let p = raw("deep-object.mdlod", deep.as_bytes());
    expect_refused(&p, &["METADATA section: invalid JSON"]);

    let mut d = Doc::parse(&b);
    d.remove(SectionKind::Metadata, 0);
    let p = d.write(dir.path(), "no-metadata.mdlod");
    expect_refused(&p, &["section table", "no METADATA section"]);
}
