//! Fuzzes the `.mdlod` reader: whatever the bytes, `MdlodFile::open` and `verify` must
//! return (an error naming the file, or a file whose every accessor stays in bounds),
//! never panic, hang or allocate without bound.
//!
//! Input: one mode byte, then the file. Random bytes almost never get past the header
//! checksum, so when bit 0 of the mode byte is set the target first recomputes every
//! checksum (sections lying inside the file, section table, header) and the stated file
//! size, which lets the fuzzer reach the structural checks behind them; when bit 1 is
//! set, open checks only the top node and the accessors check the rest as they read it
//! (what large files get). Seeds made by
//! `cargo run --example make_seeds` are valid files with mode 1.

#![no_main]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use mdlod_format::layout::{Header, SectionEntry, HEADER_SIZE};
use mdlod_format::MdlodFile;
use xxhash_rust::xxh3::xxh3_64;

/// The file each input is written to (one per process, rewritten per input).
fn input_path() -> &'static Path {
    static PATH: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    let (_, path) = PATH.get_or_init(|| {
        let dir = tempfile::tempdir().expect("temporary directory");
        let path = dir.path().join("fuzz-input.mdlod");
        (dir, path)
    });
    path
}

/// Recomputes section checksums, the table checksum, `file_size` and the header checksum,
/// as far as the header and table lie inside the bytes.
fn reseal(b: &mut [u8]) {
    if b.len() < HEADER_SIZE {
        return;
    }
    let len = b.len() as u64;
    let mut h: Header = bytemuck::pod_read_unaligned(&b[..HEADER_SIZE]);
    h.file_size = len;
    let table = u64::from(h.section_count)
        .checked_mul(32)
        .and_then(|n| h.section_table_offset.checked_add(n))
        .filter(|&end| end <= len && h.section_table_offset >= HEADER_SIZE as u64)
        .map(|end| h.section_table_offset as usize..end as usize);
    if let Some(table) = table {
        for at in table.clone().step_by(32) {
            let mut s: SectionEntry = bytemuck::pod_read_unaligned(&b[at..at + 32]);
            let end = s.offset.checked_add(s.length).filter(|&e| e <= len);
            // A section overlapping the table would change under its own checksum.
            if let Some(end) =
                end.filter(|&e| e <= table.start as u64 || s.offset >= table.end as u64)
            {
                s.checksum = xxh3_64(&b[s.offset as usize..end as usize]);
                b[at..at + 32].copy_from_slice(bytemuck::bytes_of(&s));
            }
        }
        h.section_table_checksum = xxh3_64(&b[table]);
    }
    h.header_checksum = xxh3_64(&bytemuck::bytes_of(&h)[..56]);
    b[..HEADER_SIZE].copy_from_slice(bytemuck::bytes_of(&h));
}

/// Walks the hierarchy from the top as a traversal does: a node's children are read
/// only after `check_children` passed for it.
fn walk(f: &MdlodFile) {
    let levels = f.levels();
    let last = levels.len() - 1;
    let mut stack = vec![0usize];
    while let Some(id) = stack.pop() {
        if f.check_children(id).is_err() {
            continue;
        }
        let n = &f.nodes()[id];
        let l = usize::from(n.level) + 1;
        let children = n.child_first as usize..(n.child_first + n.child_count) as usize;
        if l < last {
            let at = levels[l].node_first as usize;
            stack.extend(children.map(|c| at + c));
        } else {
            let p = f.positions(l);
            for c in children {
                let _ = p.get(c);
            }
        }
    }
}

/// Uses every accessor of an opened file, as a renderer would.
fn touch(f: &MdlodFile) {
    walk(f);
    let _ = (
        f.header(),
        f.sections().len(),
        f.metadata(),
        f.position_bits(),
    );
    let _ = (f.delta_n(), f.particle_count(), f.nodes().len());
    for l in 0..f.level_count() {
        let _ = f.levels()[l];
        for n in f.level_nodes(l) {
            let _ = n.colour_rgb();
        }
        let p = f.positions(l);
        if !p.is_empty() {
            let _ = (p.get(0), p.get(p.len() - 1), p.bytes().len());
        }
        if l >= 1 {
            let Ok(ranges) = f.encoding_ranges(l) else {
                return;
            };
            assert_eq!(ranges.iter().map(|(_, r)| r.len()).sum::<usize>(), p.len());
            assert_eq!(f.decode_level(l).map(|d| d.len()).ok(), Some(p.len()));
        }
    }
    let species = f.metadata().species.len();
    let _ = f
        .species()
        .iter()
        .filter(|&&s| usize::from(s) < species)
        .count();
    let _ = f.attribute().map(<[u16]>::len);
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, bytes)) = data.split_first() else {
        return;
    };
    let mut bytes = bytes.to_vec();
    if mode & 1 == 1 {
        reseal(&mut bytes);
    }
    let path = input_path();
    std::fs::write(path, &bytes).expect("write the input file");
    // Bit 1 of the mode byte: check the node table on open, or only the top node (the
    // rest block by block as the accessors reach it, as for large files).
    let eager = if mode & 2 == 2 { 1 } else { u64::MAX };
    let result = MdlodFile::open_with_eager_nodes(path, eager).and_then(|f| {
        touch(&f);
        f.verify().map(|_| ())
    });
    if let Err(e) = result {
        let msg = e.to_string();
        assert!(
            msg.contains("fuzz-input.mdlod"),
            "message does not name the file: {msg}"
        );
    }
});
