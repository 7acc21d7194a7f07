//! Per-processor dump pieces (`%` in a LAMMPS dump name): real pieces written by LAMMPS
//! on 2 MPI processes, merged and compared with the single-file dump of the same run.

use std::path::Path;

use mdlod_datasets::lammps_sample_path;
use mdlod_preprocess::readers::{DumpFile, ReadOptions};
use mdlod_preprocess::{Frame, NoProgress};

fn read(path: &Path, k: usize) -> Frame {
    DumpFile::open(path)
        .unwrap()
        .read_frame(
            k,
            &ReadOptions {
                attribute: Some("id".into()),
                ..Default::default()
            },
            &NoProgress,
        )
        .unwrap()
}

/// (id, position, species name) sorted by id.
fn atoms(f: &Frame) -> Vec<(u32, [f32; 3], String)> {
    let ids = &f.attribute.as_ref().unwrap().values;
    let mut v: Vec<_> = (0..f.len())
        .map(|i| {
            (
                ids[i] as u32,
                f.positions[i],
                f.species[usize::from(f.species_index[i])].name.clone(),
            )
        })
        .collect();
    v.sort_by_key(|a| a.0);
    v
}

#[test]
fn text_and_binary_pieces_merge_into_the_whole_frame() {
    let all = lammps_sample_path("cu_melt_mpi.all.dump");
    for pattern in ["cu_melt_mpi.%.dump", "cu_melt_mpi.%.bin"] {
        let path = lammps_sample_path(pattern);
        let d = DumpFile::open(&path).unwrap();
        assert_eq!(d.frame_count(), 3, "{pattern}");
        assert_eq!(d.frame_info(1).unwrap().particles, 500);
        for k in 0..3 {
            assert_eq!(d.frame_timestep(k), Some(250 * k as u64));
            let (merged, whole) = (read(&path, k), read(&all, k));
            assert_eq!(merged.len(), 500);
            // Both pieces hold atoms: the merge really joins two files.
            let first = DumpFile::open(&lammps_sample_path(&pattern.replace('%', "0")))
                .unwrap()
                .frame_info(k)
                .unwrap()
                .particles;
            assert!(first > 0 && first < 500);
            assert_eq!(merged.timestep, whole.timestep);
            for (a, b) in atoms(&merged).iter().zip(atoms(&whole)) {
                assert_eq!(a.0, b.0);
                assert_eq!(a.2, b.2);
                for ax in 0..3 {
                    // Text pieces equal the text whole; binary ones round to it.
                    assert!((a.1[ax] - b.1[ax]).abs() <= 1e-5 * (1.0 + b.1[ax].abs()));
                }
            }
        }
    }
}

#[test]
fn missing_or_disagreeing_pieces_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let copy = |from: &str, to: &str| {
        std::fs::copy(lammps_sample_path(from), dir.path().join(to)).unwrap();
    };
    // Only piece 1.
    copy("cu_melt_mpi.1.dump", "run.1.dump");
    let e = DumpFile::open(&dir.path().join("run.%.dump"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("piece 0 is missing (found 1)"), "{e}");
    // Piece 0 from another run with other frames.
    copy("cu_melt.custom.dump", "run.0.dump");
    let e = DumpFile::open(&dir.path().join("run.%.dump"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("run.1.dump: frame 1 is timestep 250") && e.contains("timestep 100"),
        "{e}"
    );
    // The same frames, one piece a frame ahead (a run writing them in turn): the frames
    // both hold, the other said.
    copy("cu_melt_mpi.0.dump", "run.0.dump");
    let text = std::fs::read_to_string(lammps_sample_path("cu_melt_mpi.1.dump")).unwrap();
    let last = text.rfind("ITEM: TIMESTEP").unwrap();
    std::fs::write(dir.path().join("run.1.dump"), &text[..last]).unwrap();
    let set = DumpFile::open(&dir.path().join("run.%.dump")).unwrap();
    assert_eq!(set.frame_count(), 2);
    let notes = set.input_notes();
    assert!(
        notes.len() == 1
            && notes[0].ends_with(
                "1 frame past the last that every piece holds (a run still writing its \
                 pieces?) left out until every piece has it"
            ),
        "{notes:?}"
    );
    assert_eq!(read(&dir.path().join("run.%.dump"), 1).positions.len(), 500);
    // The same frames at another timestep: named as timesteps, of the whole piece (no
    // line of it).
    copy("cu_melt_mpi.0.dump", "run.0.dump");
    let text = std::fs::read_to_string(lammps_sample_path("cu_melt_mpi.1.dump")).unwrap();
    let text = text.replace("ITEM: TIMESTEP\n250\n", "ITEM: TIMESTEP\n260\n");
    std::fs::write(dir.path().join("run.1.dump"), text).unwrap();
    let e = DumpFile::open(&dir.path().join("run.%.dump"))
        .unwrap_err()
        .to_string();
    let piece = dir.path().join("run.1.dump").display().to_string();
    assert!(
        e.starts_with(&format!("{piece}: frame 1 is timestep 260, but in "))
            && e.ends_with("run.0.dump it is timestep 250"),
        "{e}"
    );
    // A binary piece cut short inside its first header (a copy that stopped): said as
    // a piece whose timestep cannot be read, with where to look.
    copy("cu_melt_mpi.0.bin", "run.0.bin");
    let bytes = std::fs::read(lammps_sample_path("cu_melt_mpi.1.bin")).unwrap();
    std::fs::write(dir.path().join("run.1.bin"), &bytes[..10]).unwrap();
    let e = DumpFile::open(&dir.path().join("run.%.bin"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains(
            "run.1.bin: frame 0 is without a timestep that can be read (cut short or damaged?"
        ) && e.contains("run.0.bin it is timestep 0"),
        "{e}"
    );
    // Nothing at all.
    let e = DumpFile::open(&dir.path().join("none.%.dump"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("no files match `none.%.dump`"), "{e}");
}

/// A set a run is still writing, its last frame cut short in one piece wherever the cut
/// falls (binary: in the magic string's length or text, the timestep, the box, the column
/// names, the chunk data; text: in or after `ITEM: TIMESTEP` and its value, the box, the
/// atoms): the frames before it read, the cut frame is a "cut short" error naming the
/// piece, so the default conversion takes the last complete frame, as for one dump. A
/// complete frame at another timestep is still an error naming the piece and the frame.
#[test]
fn pieces_cut_short_in_their_last_frame_keep_the_frames_before() {
    use mdlod_preprocess::convert::{convert_file, ConvertError, ConvertOptions, FrameSelect};
    let dir = tempfile::tempdir().unwrap();
    // Bytes from frame 2's start: binary, after the magic string's length (8 bytes),
    // `DUMPCUSTOM`, the endian flag and revision, the timestep is at 26, the box at 70
    // and the chunk data at 153.
    let binary_cuts: &[usize] = &[4, 12, 29, 75, 130, 160, 6000];
    // Text: `ITEM:`, `ITEM: TIMESTEP\n`, `ITEM: TIMESTEP\n50` (a part of `500`), its
    // whole line, inside the box bounds, inside the atoms.
    let text_cuts: &[usize] = &[5, 15, 17, 19, 120, 400];
    for (ext, cuts) in [("bin", binary_cuts), ("dump", text_cuts)] {
        let whole: Vec<Vec<u8>> = (0..2)
            .map(|k| std::fs::read(lammps_sample_path(&format!("cu_melt_mpi.{k}.{ext}"))).unwrap())
            .collect();
        for cut_piece in 0..2 {
            let source = lammps_sample_path(&format!("cu_melt_mpi.{cut_piece}.{ext}"));
            let third = DumpFile::open(&source).unwrap().frame_bytes(2).unwrap();
            let (start, end) = (third.start as usize, third.end as usize);
            if ext == "bin" {
                let timestep = &whole[cut_piece][start + 26..start + 34];
                assert_eq!(i64::from_le_bytes(timestep.try_into().unwrap()), 500);
            }
            for &cut in cuts {
                let at = start + cut;
                assert!(at < end);
                let case =
                    format!("piece {cut_piece} of the .{ext} set cut {cut} bytes into frame 2");
                for (k, bytes) in whole.iter().enumerate() {
                    let bytes = if k == cut_piece {
                        &bytes[..at]
                    } else {
                        &bytes[..]
                    };
                    std::fs::write(dir.path().join(format!("run.{k}.{ext}")), bytes).unwrap();
                }
                let set = dir.path().join(format!("run.%.{ext}"));
                let d = DumpFile::open(&set).unwrap_or_else(|e| panic!("{case}: {e}"));
                assert_eq!(d.frame_count(), 3, "{case}");
                assert_eq!(
                    (d.frame_timestep(0), d.frame_timestep(1)),
                    (Some(0), Some(250))
                );
                assert!(d.input_notes().is_empty(), "{case}: {:?}", d.input_notes());
                for k in 0..2 {
                    assert_eq!(read(&set, k).len(), 500, "{case}");
                }
                let e = d
                    .read_frame(2, &ReadOptions::default(), &NoProgress)
                    .unwrap_err();
                let piece = dir.path().join(format!("run.{cut_piece}.{ext}"));
                assert!(
                    e.cut_short() && e.to_string().starts_with(&piece.display().to_string()),
                    "{case}: {e}"
                );
                let convert = |frame| {
                    convert_file(
                        &set,
                        &dir.path().join("out.mdlod"),
                        frame,
                        &ReadOptions::default(),
                        &ConvertOptions::default(),
                        &NoProgress,
                    )
                };
                match convert(FrameSelect::Last) {
                    Err(ConvertError::LastFrameIncomplete { frame: 2, .. }) => {}
                    r => panic!("{case}: {:?}", r.map(|r| r.frame)),
                }
                for k in 0..2 {
                    let r =
                        convert(FrameSelect::Index(k)).unwrap_or_else(|e| panic!("{case}: {e}"));
                    assert_eq!((r.particles, r.frame), (500, Some((k, 3))), "{case}");
                }
            }
        }
    }
    // A complete frame at another timestep before the cut one: still an error, naming
    // the piece and the frame.
    let mut changed = std::fs::read(lammps_sample_path("cu_melt_mpi.1.bin")).unwrap();
    let second = DumpFile::open(&lammps_sample_path("cu_melt_mpi.1.bin"))
        .unwrap()
        .frame_bytes(1)
        .unwrap();
    let at = second.start as usize + 26;
    changed[at..at + 8].copy_from_slice(&260i64.to_le_bytes());
    std::fs::write(
        dir.path().join("run.1.bin"),
        &changed[..second.end as usize + 100],
    )
    .unwrap();
    std::fs::copy(
        lammps_sample_path("cu_melt_mpi.0.bin"),
        dir.path().join("run.0.bin"),
    )
    .unwrap();
    let e = DumpFile::open(&dir.path().join("run.%.bin"))
        .unwrap_err()
        .to_string();
    let piece = dir.path().join("run.1.bin").display().to_string();
    assert!(
        e.starts_with(&format!("{piece}: frame 1 is timestep 260, but in "))
            && e.ends_with("run.0.bin it is timestep 250"),
        "{e}"
    );
}

#[test]
fn piece_counts_that_add_up_past_any_count_are_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let piece = |i: usize, atoms: &str| {
        let text = format!(
            "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{atoms}\nITEM: BOX BOUNDS pp pp pp\n\
             0 1\n0 1\n0 1\nITEM: ATOMS id type x y z\n{} 1 0.5 0.5 0.5\n",
            i + 1
        );
        std::fs::write(dir.path().join(format!("run.{i}.dump")), text).unwrap();
    };
    // Two pieces announcing 2^64 - 1 atoms each (a sum past any count): each piece's
    // count is more than its bytes can hold, said of the first, before any sum.
    piece(0, "18446744073709551615");
    piece(1, "18446744073709551615");
    let d = DumpFile::open(&dir.path().join("run.%.dump")).unwrap();
    let e = d.frame_info(0).unwrap_err().to_string();
    let first = dir.path().join("run.0.dump");
    assert!(
        e.starts_with(&format!("{}:10: truncated frame", first.display()))
            && e.contains("announces 18446744073709551615 atoms but only 1 atom lines follow"),
        "{e}"
    );
    // Counts that add up are the sum (read, the pieces hold one atom each).
    piece(0, "1");
    piece(1, "1");
    let d = DumpFile::open(&dir.path().join("run.%.dump")).unwrap();
    assert_eq!(d.frame_info(0).unwrap().particles, 2);
}

/// A piece of type numbers (2 before 1) and a piece that also uses a type label: the
/// merged frame lists its species as the single dump of the same atoms does, in order of
/// first appearance (not all are numbers), not in the first piece's numeric order.
#[test]
fn pieces_of_numbers_and_labels_list_species_as_the_whole_dump() {
    let dir = tempfile::tempdir().unwrap();
    let dump = |atoms: &[(u32, &str)]| {
        let mut s = format!(
            "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{}\nITEM: BOX BOUNDS pp pp pp\n\
             0 10\n0 10\n0 10\nITEM: ATOMS id type x y z\n",
            atoms.len()
        );
        for (id, t) in atoms {
            s.push_str(&format!("{id} {t} {id}.5 1 2\n"));
        }
        s
    };
    let first: [(u32, &str); 3] = [(1, "2"), (2, "1"), (3, "2")];
    let second: [(u32, &str); 2] = [(4, "O"), (5, "1")];
    std::fs::write(dir.path().join("mix.0.dump"), dump(&first)).unwrap();
    std::fs::write(dir.path().join("mix.1.dump"), dump(&second)).unwrap();
    let all: Vec<_> = first.iter().chain(&second).copied().collect();
    std::fs::write(dir.path().join("mix.all.dump"), dump(&all)).unwrap();
    let names = |f: &Frame| -> Vec<String> { f.species.iter().map(|s| s.name.clone()).collect() };
    let merged = read(&dir.path().join("mix.%.dump"), 0);
    let whole = read(&dir.path().join("mix.all.dump"), 0);
    assert_eq!(names(&whole), ["2", "1", "O"]);
    assert_eq!(names(&merged), names(&whole));
    assert_eq!(atoms(&merged), atoms(&whole));
}

/// One processor's piece converted alone reads that piece's atoms only: the conversion
/// says which set to give. A series of timesteps named alike is no set of pieces.
#[test]
fn one_piece_given_alone_names_its_set() {
    use mdlod_preprocess::convert::{convert_file, ConvertOptions, FrameSelect};
    let dir = tempfile::tempdir().unwrap();
    for n in ["cu_melt_mpi.0.dump", "cu_melt_mpi.1.dump"] {
        std::fs::copy(lammps_sample_path(n), dir.path().join(n)).unwrap();
    }
    let convert = |input: &Path| {
        convert_file(
            input,
            &dir.path().join("out.mdlod"),
            FrameSelect::Last,
            &ReadOptions::default(),
            &ConvertOptions::default(),
            &NoProgress,
        )
        .unwrap()
        .notes
    };
    let notes = convert(&dir.path().join("cu_melt_mpi.0.dump"));
    let want = format!(
        "cu_melt_mpi.0.dump may be one processor's piece of a `%` set: cu_melt_mpi.1.dump \
         starts at timestep 0 too (2 pieces); if it is, only this piece's \
         particles were read: give '{}' (quoted)",
        dir.path().join("cu_melt_mpi.%.dump").display()
    );
    assert!(notes.iter().any(|n| n.starts_with(&want)), "{notes:?}");
    // The set itself: no such note.
    let notes = convert(&dir.path().join("cu_melt_mpi.%.dump"));
    assert!(!notes.iter().any(|n| n.contains("piece")), "{notes:?}");
    // Files of other timesteps named alike.
    let series = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(lammps_sample_path("cu_melt.custom.dump")).unwrap();
    let second = text
        .find("ITEM: TIME\n")
        .and_then(|i| text[i + 1..].find("ITEM: TIME\n").map(|j| i + 1 + j))
        .unwrap();
    std::fs::write(series.path().join("melt.0.dump"), &text[..second]).unwrap();
    std::fs::write(series.path().join("melt.100.dump"), &text[second..]).unwrap();
    let notes = convert(&series.path().join("melt.0.dump"));
    assert!(!notes.iter().any(|n| n.contains("piece")), "{notes:?}");
    // Two variants of one frame (the same atoms, another column) start alike: no pieces.
    let variants = tempfile::tempdir().unwrap();
    std::fs::write(variants.path().join("const1.dump"), &text[..second]).unwrap();
    std::fs::write(variants.path().join("const5.dump"), &text[..second]).unwrap();
    let notes = convert(&variants.path().join("const5.dump"));
    assert!(!notes.iter().any(|n| n.contains("piece")), "{notes:?}");
}

/// In a batch over one processor's piece of every timestep (`'melt.*.0.dump'`), the note
/// names the pattern of every timestep's set, not one timestep's.
#[test]
fn a_batch_of_one_piece_per_timestep_is_pointed_to_every_timesteps_set() {
    let dir = tempfile::tempdir().unwrap();
    // The real pieces' frames, a file per timestep and processor.
    for piece in 0..2 {
        let text =
            std::fs::read_to_string(lammps_sample_path(&format!("cu_melt_mpi.{piece}.dump")))
                .unwrap();
        for frame in text.split("ITEM: TIMESTEP\n").skip(1) {
            let timestep: u64 = frame.lines().next().unwrap().trim().parse().unwrap();
            std::fs::write(
                dir.path().join(format!("melt.{timestep}.{piece}.dump")),
                format!("ITEM: TIMESTEP\n{frame}"),
            )
            .unwrap();
        }
    }
    let mut inputs: Vec<std::path::PathBuf> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().ends_with(".0.dump"))
        .collect();
    inputs.sort();
    let opts = mdlod_preprocess::batch::BatchOptions {
        memory_limit: 1 << 30,
        ..Default::default()
    };
    let r = mdlod_preprocess::batch::batch(&inputs, &dir.path().join("out"), &opts, &NoProgress)
        .unwrap();
    let give = format!("give '{}'", dir.path().join("melt.*.%.dump").display());
    assert!(r.notes.iter().any(|n| n.contains(&give)), "{:?}", r.notes);
}
