//! Batch conversion of whole trajectories: manifest, resuming, shards and merging.

use std::path::{Path, PathBuf};

use mdlod_datasets::lammps_sample_path;
use mdlod_format::MdlodFile;
use mdlod_preprocess::batch::{
    batch, merge, read_manifest, verify_dir, BatchError, BatchOptions, Manifest, INDEX_CACHE,
};
use mdlod_preprocess::NoProgress;

fn opts() -> BatchOptions {
    BatchOptions {
        memory_limit: 1 << 30,
        ..Default::default()
    }
}

/// [`opts`] for shard `i` of `n`.
fn shard(i: u32, n: u32) -> BatchOptions {
    BatchOptions {
        shard: Some((i, n)),
        ..opts()
    }
}

/// A copy of the 6-frame real dump (so its modification time can change).
fn input(dir: &Path) -> PathBuf {
    let p = dir.join("melt.dump");
    std::fs::copy(lammps_sample_path("cu_melt.custom.dump"), &p).unwrap();
    p
}

fn check_manifest(dir: &Path, m: &Manifest) {
    for f in &m.frames {
        let file = MdlodFile::open(dir.join(&f.file)).unwrap();
        file.verify().unwrap();
        assert_eq!(file.metadata().timestep, Some(f.timestep));
        assert_eq!(
            format!("{:016x}", file.header().section_table_checksum),
            f.checksum
        );
        assert_eq!(file.particle_count(), f.particles);
    }
}

#[test]
fn every_frame_converts_once_and_reruns_redo_only_what_changed() {
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let out = dir.path().join("out");
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.frames_total, r.converted, r.skipped), (6, 6, 0));
    let m = read_manifest(&out).unwrap();
    assert_eq!(
        m.frames.iter().map(|f| f.timestep).collect::<Vec<_>>(),
        [0, 100, 200, 300, 400, 500]
    );
    assert_eq!(m.frames[3].file, "frame-300.mdlod");
    assert_eq!(m.frames[3].time, Some(0.6));
    assert_eq!(m.frames[3].source.frame, 3);
    assert!(m.frames[0].simulation_box.is_some());
    check_manifest(&out, &m);

    // Nothing changed: nothing to do.
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped), (0, 6));

    // A lost output and a leftover temporary file of a killed run.
    std::fs::remove_file(out.join("frame-300.mdlod")).unwrap();
    std::fs::write(out.join(".frame-100.mdlod.abc123.tmp"), b"partial").unwrap();
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped), (1, 5));
    assert!(!out.join(".frame-100.mdlod.abc123.tmp").exists());
    let again = read_manifest(&out).unwrap();
    assert_eq!(again, m, "the redone frame is byte-identical");

    // A changed modification time: every frame's bytes are compared, and kept.
    let f = std::fs::File::options().write(true).open(&src).unwrap();
    f.set_modified(std::time::SystemTime::UNIX_EPOCH + std::time::Duration::from_secs(1_000_000))
        .unwrap();
    drop(f);
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped, r.kept_unchanged), (0, 6, 6));

    // Written again within the same second, to the same size: told apart by the
    // nanoseconds of its modification time, so the bytes are compared again.
    let f = std::fs::File::options().write(true).open(&src).unwrap();
    f.set_modified(
        std::time::SystemTime::UNIX_EPOCH + std::time::Duration::new(1_000_000, 500_000_000),
    )
    .unwrap();
    drop(f);
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!(
        (r.converted, r.skipped, r.kept_unchanged),
        (0, 6, 6),
        "same second, other nanoseconds"
    );
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped, r.kept_unchanged), (0, 6, 0));

    // Replaced by another run's dump of the same frames: everything is redone.
    let mut other = std::fs::read(&src).unwrap();
    let at = other.len() / 7;
    let digit = (at..other.len()).find(|&i| other[i] == b'1').unwrap();
    other[digit] = b'2';
    std::fs::write(&src, &other).unwrap();
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!(
        (r.converted, r.redone.source),
        (1, 1),
        "only frame 0's bytes changed"
    );
}

#[test]
fn shards_merge_into_the_manifest_of_an_unsharded_run() {
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let whole = dir.path().join("whole");
    batch(std::slice::from_ref(&src), &whole, &opts(), &NoProgress).unwrap();
    let sharded = dir.path().join("sharded");
    let mut counts = vec![];
    for i in 0..4 {
        let o = shard(i, 4);
        let r = batch(std::slice::from_ref(&src), &sharded, &o, &NoProgress).unwrap();
        counts.push(r.frames_in_shard);
        // Not all shards yet: every missing one is named.
        if i == 1 {
            let e = merge(&sharded).unwrap_err().to_string();
            assert!(
                e.contains(
                    "shards 2, 3 of 4 have no manifest yet (the manifests of shards 0, 1 are \
                     there): run or rerun them before merging"
                ),
                "{e}"
            );
        }
        if i == 2 {
            let e = merge(&sharded).unwrap_err().to_string();
            assert!(
                e.contains("shard 3 of 4 has no manifest yet (the manifests of shards 0, 1, 2"),
                "{e}"
            );
        }
    }
    assert_eq!(counts, [2, 2, 1, 1]);
    let merged = merge(&sharded).unwrap();
    let reference = read_manifest(&whole).unwrap();
    assert_eq!(merged.frames, reference.frames);
    assert_eq!(read_manifest(&sharded).unwrap(), merged);
    check_manifest(&sharded, &merged);
}

#[test]
fn conflicting_inputs_and_bad_shards_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let a = input(dir.path());
    let b = lammps_sample_path("cu_melt.step.0.bin");
    let e = batch(&[a.clone(), b], &dir.path().join("o"), &opts(), &NoProgress).unwrap_err();
    assert!(
        matches!(e, BatchError::DuplicateTimestep { timestep: 0, .. }),
        "{e}"
    );
    assert!(
        e.to_string().contains("melt.dump frame 0")
            && e.to_string().contains("cu_melt.step.0.bin frame 0")
    );
    let o = shard(4, 4);
    assert!(matches!(
        batch(&[a], &dir.path().join("o"), &o, &NoProgress),
        Err(BatchError::BadShard(4, 4))
    ));
    let e = merge(dir.path()).unwrap_err().to_string();
    assert!(e.contains("no shard manifests"), "{e}");
}

#[test]
fn frames_above_the_chunk_size_are_built_out_of_core_and_match_convert() {
    // The real binary dump (3 frames of 500 atoms), in chunks of 300 read 128 at a time.
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("melt.bin");
    std::fs::copy(lammps_sample_path("cu_melt.custom.bin"), &src).unwrap();
    let mut o = opts();
    o.convert.build.max_root_points = 64;
    o.convert.chunks.chunk_points = 300;
    o.convert.chunks.window_points = 128;
    let out = dir.path().join("out");
    let r = batch(std::slice::from_ref(&src), &out, &o, &NoProgress).unwrap();
    assert!(r.converted >= 2);
    let m = read_manifest(&out).unwrap();
    check_manifest(&out, &m);
    // Working files are gone: only frames and the manifest remain (and the run's lock).
    for e in std::fs::read_dir(&out).unwrap() {
        let name = e.unwrap().file_name().to_string_lossy().into_owned();
        assert!(
            name.starts_with("frame-") || name == "dataset.json" || name == ".batch.lock",
            "left behind: {name}"
        );
    }
    // Each frame's hierarchy equals `convert`'s of the same frame (the metadata's
    // source records differ only in how they name the input).
    for (k, f) in m.frames.iter().enumerate() {
        let file = MdlodFile::open(out.join(&f.file)).unwrap();
        assert_eq!(file.metadata().build.chunk_points, Some(300));
        let single = dir.path().join(format!("single-{k}.mdlod"));
        mdlod_preprocess::convert::convert_file(
            &src,
            &single,
            mdlod_preprocess::convert::FrameSelect::Index(k),
            &o.read,
            &o.convert,
            &NoProgress,
        )
        .unwrap();
        let other = MdlodFile::open(&single).unwrap();
        assert!(file.nodes() == other.nodes(), "frame {k}: nodes differ");
        assert_eq!(file.species(), other.species());
        let last = file.level_count() - 1;
        assert_eq!(file.positions(last).bytes(), other.positions(last).bytes());
    }
}

#[test]
fn gzip_inputs_are_reopened_by_their_worker_and_large_ones_decompressed_to_working_files() {
    // The 6-frame real dump, gzip-compressed, three ways: frames in memory, decompressed
    // into a working file per worker, and above the chunk size (read in windows from it).
    let dir = tempfile::tempdir().unwrap();
    let gz = dir.path().join("melt.dump.gz");
    std::fs::copy(lammps_sample_path("cu_melt.custom.dump.gz"), &gz).unwrap();
    let work = dir.path().join("work");
    std::fs::create_dir(&work).unwrap();
    let run = |name: &str, spool: bool, chunk: Option<usize>| {
        let mut o = opts();
        o.convert.chunks.temp_dir = Some(work.clone());
        o.convert.chunks.gzip_in_memory = spool.then_some(0);
        o.convert.build.max_root_points = 64;
        if let Some(c) = chunk {
            o.convert.chunks.chunk_points = c;
            o.convert.chunks.window_points = 128;
        }
        let out = dir.path().join(name);
        let r = batch(std::slice::from_ref(&gz), &out, &o, &NoProgress).unwrap();
        assert_eq!(r.converted, 6, "{name}");
        let m = read_manifest(&out).unwrap();
        check_manifest(&out, &m);
        assert_eq!(
            std::fs::read_dir(&work).unwrap().count(),
            0,
            "{name}: working files left"
        );
        m
    };
    let in_memory = run("a", false, None);
    let spooled = run("b", true, None);
    // The same frames from the same source: identical files.
    assert_eq!(in_memory.frames, spooled.frames);
    let chunked = run("c", true, Some(300));
    let whole = run("d", false, Some(300));
    assert_eq!(chunked.frames, whole.frames);
}

/// A 3-frame XYZ trajectory: no timesteps, so frames are numbered by position.
fn xyz_trajectory(dir: &Path) -> PathBuf {
    let p = dir.join("traj.xyz");
    let mut text = String::new();
    for frame in 0..3 {
        text.push_str("40\nframe without a timestep\n");
        for i in 0..40 {
            let x = (i % 4) as f64 * 2.0 + frame as f64 * 0.1;
            let y = ((i / 4) % 5) as f64 * 2.0;
            let z = (i / 20) as f64 * 2.0;
            text.push_str(&format!("Ar {x} {y} {z}\n"));
        }
    }
    std::fs::write(&p, text).unwrap();
    p
}

/// An XYZ trajectory whose frames give a timestep in some comment lines and none in
/// others is refused, naming both (numbered by position, the frames without one would
/// play out of order); a last frame cut short before its comment line is not counted.
#[test]
fn frames_with_and_without_timesteps_in_one_input_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let frame = |comment: &str| format!("2\n{comment}\nAr 0 0 0\nAr 1 1 1\n");
    let src = dir.path().join("mixed.xyz");
    let text = [
        frame("Time=0.0"),
        frame("Time=1.0 step=100"),
        frame("Time=2.0 step=200"),
        frame("Time=3.0"),
    ]
    .concat();
    std::fs::write(&src, &text).unwrap();
    let e = batch(
        std::slice::from_ref(&src),
        &dir.path().join("out"),
        &opts(),
        &NoProgress,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("mixed.xyz: frames 1 and 2 give a timestep, but frames 0 and 3 give none"),
        "{e}"
    );
    // Stepped frames and a last one a run is still writing (cut before its comment).
    let text = [frame("step=0"), frame("step=100"), "2\n".to_string()].concat();
    std::fs::write(&src, text).unwrap();
    let r = batch(
        std::slice::from_ref(&src),
        &dir.path().join("out2"),
        &opts(),
        &NoProgress,
    )
    .unwrap();
    assert_eq!(r.converted, 2, "{r:?}");
}

#[test]
fn frames_without_timesteps_are_listed_by_position_and_shards_merge() {
    let dir = tempfile::tempdir().unwrap();
    let src = xyz_trajectory(dir.path());
    let whole = dir.path().join("whole");
    batch(std::slice::from_ref(&src), &whole, &opts(), &NoProgress).unwrap();
    let m = read_manifest(&whole).unwrap();
    assert_eq!(
        m.frames
            .iter()
            .map(|f| (f.timestep, f.file.as_str(), f.source.frame))
            .collect::<Vec<_>>(),
        [
            (0, "frame-0.mdlod", 0),
            (1, "frame-1.mdlod", 1),
            (2, "frame-2.mdlod", 2)
        ]
    );
    assert_eq!(m.expected_frames, Some(3));
    let sharded = dir.path().join("sharded");
    for i in 0..2 {
        let o = shard(i, 2);
        batch(std::slice::from_ref(&src), &sharded, &o, &NoProgress).unwrap();
    }
    assert_eq!(merge(&sharded).unwrap().frames, m.frames);
}

#[test]
fn merge_refuses_a_shard_that_has_not_finished() {
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let out = dir.path().join("d");
    for i in 0..2 {
        let o = shard(i, 2);
        batch(std::slice::from_ref(&src), &out, &o, &NoProgress).unwrap();
    }
    // Shard 1 as a killed run leaves it: one frame not yet listed.
    let path = out.join("dataset.shard-1-of-2.json");
    let mut m: Manifest = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    assert_eq!((m.frames.len(), m.expected_frames), (3, Some(3)));
    m.frames.pop();
    std::fs::write(&path, serde_json::to_vec(&m).unwrap()).unwrap();
    let e = merge(&out).unwrap_err().to_string();
    assert!(
        e.contains("dataset.shard-1-of-2.json") && e.contains("lists 2 of the shard's 3 frames"),
        "{e}"
    );
    // Rerunning the shard completes it (the frame no manifest records converted
    // again), and the merge goes through.
    let o = shard(1, 2);
    let r = batch(std::slice::from_ref(&src), &out, &o, &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped, r.redone.unrecorded), (1, 2, 1));
    let merged = merge(&out).unwrap();
    assert_eq!((merged.frames.len(), merged.expected_frames), (6, Some(6)));
}

#[test]
fn a_shard_removes_only_its_own_leftovers_and_stale_manifests() {
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let out = dir.path().join("d");
    std::fs::create_dir_all(&out).unwrap();
    // Timesteps 0, 200, 400 are shard 0's; 100, 300, 500 shard 1's.
    let leftover = |name: &str| {
        let p = out.join(name);
        std::fs::write(&p, b"partial").unwrap();
        p
    };
    let own = leftover(".frame-200.mdlod.k1ll3d.tmp");
    let others = leftover(".frame-300.mdlod.wr1t1n.tmp");
    let fresh_manifest = leftover(".dataset.fr35h.tmp");
    // A directory named like a leftover is not one.
    let not_ours = out.join(".frame-0.mdlod.d1r.tmp");
    std::fs::create_dir(&not_ours).unwrap();
    let stale_manifest = leftover(".dataset.0ld.tmp");
    let f = std::fs::File::options()
        .write(true)
        .open(&stale_manifest)
        .unwrap();
    f.set_modified(std::time::SystemTime::now() - 2 * mdlod_preprocess::batch::STALE_TEMP)
        .unwrap();
    drop(f);
    let o = shard(0, 2);
    batch(std::slice::from_ref(&src), &out, &o, &NoProgress).unwrap();
    assert!(!own.exists(), "this shard's leftover is removed");
    assert!(
        !stale_manifest.exists(),
        "an old temporary manifest is removed"
    );
    assert!(others.exists(), "another shard's file in the making stays");
    assert!(fresh_manifest.exists(), "a manifest being written stays");
    assert!(not_ours.is_dir());
}

#[test]
fn changed_build_settings_redo_the_frames() {
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let out = dir.path().join("d");
    batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    let mut o = opts();
    o.convert.build.position_bits = 8;
    let r = batch(std::slice::from_ref(&src), &out, &o, &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped), (6, 0), "position bits changed");
    let r = batch(std::slice::from_ref(&src), &out, &o, &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped), (0, 6), "nothing changed");
    // The largest δn, past the frames' levels: recorded as the δn in effect, which a
    // rerun with the same settings recognises.
    let levels = MdlodFile::open(out.join("frame-0.mdlod"))
        .unwrap()
        .level_count();
    assert!(levels < 9, "{levels} levels");
    o.convert.build.delta_n = 8;
    batch(std::slice::from_ref(&src), &out, &o, &NoProgress).unwrap();
    let r = batch(std::slice::from_ref(&src), &out, &o, &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped), (0, 6), "δn past the levels");
    let species = MdlodFile::open(out.join("frame-0.mdlod"))
        .unwrap()
        .metadata()
        .species[0]
        .clone();
    o.convert.radii = vec![(species.name.clone(), species.radius * 2.0)];
    let r = batch(std::slice::from_ref(&src), &out, &o, &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped), (6, 0), "a radius changed");
    let file = MdlodFile::open(out.join("frame-0.mdlod")).unwrap();
    assert_eq!(file.metadata().species[0].radius, species.radius * 2.0);
}

/// A species that appears in later frames only (a deposition): a radius given for it
/// holds where it is present, and the frames without it convert too (a single frame's
/// conversion refuses an override naming none of its species; a trajectory's may not).
#[test]
fn a_radius_for_a_species_of_later_frames_only_converts_every_frame() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("deposit.xyz");
    let mut text = String::new();
    for frame in 0..3 {
        text.push_str("40\nframe\n");
        for i in 0..40 {
            let element = if frame == 2 && i % 5 == 0 { "Ag" } else { "Cu" };
            let (x, y, z) = ((i % 4) * 2, ((i / 4) % 5) * 2, (i / 20) * 2);
            text.push_str(&format!("{element} {x} {y} {z}\n"));
        }
    }
    std::fs::write(&src, text).unwrap();
    let out = dir.path().join("out");
    let mut o = opts();
    o.convert.radii = vec![("Ag".into(), 1.44)];
    let report = batch(std::slice::from_ref(&src), &out, &o, &NoProgress).unwrap();
    assert_eq!((report.converted, report.skipped), (3, 0));
    let m = read_manifest(&out).unwrap();
    assert_eq!(m.frames.len(), 3);
    let last = MdlodFile::open(out.join(&m.frames[2].file)).unwrap();
    let ag = last
        .metadata()
        .species
        .iter()
        .find(|s| s.name == "Ag")
        .unwrap();
    assert_eq!(ag.radius, 1.44);
    // A rerun finds every frame built with these settings.
    let again = batch(std::slice::from_ref(&src), &out, &o, &NoProgress).unwrap();
    assert_eq!((again.converted, again.skipped), (0, 3));
}

/// What a rerun compares a file's attribute with is the name the reader gives it (GSD
/// prefixes `particles/`, a raw sidecar's attribute is read also unasked), resolved
/// without reading the particles: for every format it equals what reading the frame
/// gives, error included, and an unchanged request finds every frame done.
#[test]
fn a_frames_attribute_is_resolved_as_reading_it_names_it_in_every_format() {
    use mdlod_datasets::{gsd_sample_path, write_raw_arrays, GenerateOptions, Kind};
    use mdlod_preprocess::readers::{DumpFile, ReadOptions};

    let dir = tempfile::tempdir().unwrap();
    let (raw, _) = write_raw_arrays(
        &GenerateOptions::new(Kind::Alloy, 500),
        dir.path(),
        "alloy",
        |_| {},
    )
    .unwrap();
    let megamol = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../datasets/megamol/test_xyz_float_int_float.mmpld");
    let cases: Vec<(PathBuf, &str)> = vec![
        (lammps_sample_path("cu_melt.custom.dump"), "c_pe"),
        (lammps_sample_path("cu_melt.custom.dump.gz"), "c_ke"),
        (lammps_sample_path("cu_melt.custom.bin"), "c_pe"),
        (lammps_sample_path("cu_melt_mpi.%.dump"), "c_pe"),
        (lammps_sample_path("cu_melt.xyz"), "x"),
        (gsd_sample_path("hoomd_mixture.gsd"), "charge"),
        (megamol, "intensity"),
        (raw.clone(), "c_pe"),
    ];
    for (input, column) in &cases {
        let dump = DumpFile::open(input).unwrap();
        for attribute in [None, Some(column.to_string()), Some("nosuch".to_string())] {
            let read = ReadOptions {
                attribute,
                ..Default::default()
            };
            for k in 0..dump.frame_count() {
                let resolved = dump.attribute_name(k, &read).map_err(|e| e.to_string());
                let from_frame = dump
                    .read_frame(k, &read, &NoProgress)
                    .map(|f| f.attribute.map(|a| a.name))
                    .map_err(|e| e.to_string());
                assert_eq!(
                    resolved,
                    from_frame,
                    "{} frame {k}: {read:?}",
                    input.display()
                );
            }
        }
    }
    // Reruns of the formats whose recorded name is not the one asked for.
    for (input, attribute) in [
        (gsd_sample_path("hoomd_mixture.gsd"), Some("charge")),
        (raw, None),
    ] {
        let out = dir.path().join(format!(
            "{}.d",
            input.file_name().unwrap().to_string_lossy()
        ));
        let mut o = opts();
        o.read.attribute = attribute.map(String::from);
        let first = batch(std::slice::from_ref(&input), &out, &o, &NoProgress).unwrap();
        assert_eq!(first.skipped, 0);
        let again = batch(std::slice::from_ref(&input), &out, &o, &NoProgress).unwrap();
        assert_eq!(
            (again.converted, again.skipped),
            (0, first.converted),
            "{}",
            input.display()
        );
    }
}

/// The radius of species `name` in every frame of a batch directory's manifest.
fn radii_of(out: &Path, name: &str) -> Vec<f32> {
    read_manifest(out)
        .unwrap()
        .frames
        .iter()
        .map(|f| {
            let file = MdlodFile::open(out.join(&f.file)).unwrap();
            file.metadata()
                .species
                .iter()
                .find(|s| s.name == name)
                .unwrap()
                .radius
        })
        .collect()
}

/// A radius given by an earlier run and left out now must not survive a rerun: the
/// species take their own radius again (the input's, as GSD diameters give it, or the
/// default), and a rerun after that finds every frame done.
#[test]
fn a_rerun_without_a_radius_given_before_gives_the_species_their_own_again() {
    use mdlod_datasets::gsd_sample_path;
    let dir = tempfile::tempdir().unwrap();
    for (src, name, own) in [
        (gsd_sample_path("hoomd_mixture.gsd"), "B", 0.75),
        (input(dir.path()), "1", 0.5),
    ] {
        let out = dir
            .path()
            .join(format!("{}.d", src.file_name().unwrap().to_string_lossy()));
        let mut o = opts();
        o.convert.radii = vec![(name.into(), 2.0)];
        let first = batch(std::slice::from_ref(&src), &out, &o, &NoProgress).unwrap();
        let n = first.converted;
        assert!(n >= 3);
        assert_eq!(radii_of(&out, name), vec![2.0; n]);
        let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
        assert_eq!((r.converted, r.skipped), (n, 0), "{}", src.display());
        assert_eq!(radii_of(&out, name), vec![own; n]);
        let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
        assert_eq!((r.converted, r.skipped), (0, n), "{}", src.display());
        // The input's own radius given explicitly builds the same file.
        o.convert.radii = vec![(name.into(), own)];
        let r = batch(std::slice::from_ref(&src), &out, &o, &NoProgress).unwrap();
        assert_eq!((r.converted, r.skipped), (0, n), "{}", src.display());
    }
}

/// A frame above the chunk size is built in chunks, and the chunk size decides the file
/// (FORMAT.md, "Chunked builds"): a rerun with another one converts such frames again; for
/// frames below both sizes nothing changes.
#[test]
fn a_rerun_with_another_chunk_size_converts_the_frames_it_changes() {
    // The real binary dump: 3 frames of 500 atoms.
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("melt.bin");
    std::fs::copy(lammps_sample_path("cu_melt.custom.bin"), &src).unwrap();
    let out = dir.path().join("out");
    let run = |chunk_points: usize| {
        let mut o = opts();
        o.convert.build.max_root_points = 64;
        o.convert.chunks.chunk_points = chunk_points;
        let r = batch(std::slice::from_ref(&src), &out, &o, &NoProgress).unwrap();
        (r.converted, r.skipped)
    };
    assert_eq!(run(300), (3, 0));
    assert_eq!(run(300), (0, 3));
    let chunks = || {
        MdlodFile::open(out.join("frame-0.mdlod"))
            .unwrap()
            .metadata()
            .build
            .chunk_points
    };
    assert_eq!(run(400), (3, 0), "another chunk size");
    assert_eq!(chunks(), Some(400));
    assert_eq!(run(1000), (3, 0), "whole frames now");
    assert_eq!(chunks(), None);
    assert_eq!(run(5000), (0, 3), "whole frames either way");
    assert_eq!(run(300), (3, 0), "chunks again");
}

/// Column names given for an old-revision LAMMPS binary dump (which names none) decide
/// what its values are, and the file does not record them: the manifest does, and a
/// rerun with other names converts the frames again.
#[test]
fn a_rerun_with_other_column_names_for_a_binary_dump_converts_again() {
    use mdlod_preprocess::readers::DumpFile;
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("melt.bin");
    let new = lammps_sample_path("cu_melt.custom.bin");
    let own = DumpFile::open(&new).unwrap().frame_info(0).unwrap().columns;
    std::fs::write(
        &src,
        mdlod_datasets::to_old_revision(&std::fs::read(&new).unwrap()),
    )
    .unwrap();
    let swapped: Vec<String> = own
        .iter()
        .map(|c| match c.as_str() {
            "x" => "y".to_string(),
            "y" => "x".to_string(),
            other => other.to_string(),
        })
        .collect();
    assert_ne!(own, swapped);
    let out = dir.path().join("out");
    let run = |columns: Option<&Vec<String>>| {
        let mut o = opts();
        o.read.columns = columns.cloned();
        let r = batch(std::slice::from_ref(&src), &out, &o, &NoProgress).unwrap();
        (r.converted, r.skipped)
    };
    let first_checksum = || read_manifest(&out).unwrap().frames[0].checksum.clone();
    assert_eq!(run(Some(&own)), (3, 0));
    let plain = first_checksum();
    assert_eq!(run(Some(&own)), (0, 3));
    assert_eq!(run(Some(&swapped)), (3, 0), "x and y swapped");
    assert_ne!(first_checksum(), plain);
    assert_eq!(
        read_manifest(&out).unwrap().frames[0].columns.as_ref(),
        Some(&swapped)
    );
    assert_eq!(run(Some(&swapped)), (0, 3));
    assert_eq!(run(Some(&own)), (3, 0), "the right names again");
    assert_eq!(first_checksum(), plain);
}

/// An MMPLD file (version 1.2) of `frames`, each a list of particle lists (vertex type 1,
/// no colour, radius 0.5) given by their particle counts.
fn mmpld(frames: &[&[usize]]) -> Vec<u8> {
    let mut out = b"MMPLD\0".to_vec();
    out.extend_from_slice(&102u16.to_le_bytes());
    out.extend_from_slice(&(frames.len() as u32).to_le_bytes());
    for v in [
        0f32, 0.0, 0.0, 10.0, 10.0, 10.0, 0.0, 0.0, 0.0, 10.0, 10.0, 10.0,
    ] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    let table = out.len();
    out.resize(table + 8 * (frames.len() + 1), 0);
    for (k, lists) in frames.iter().enumerate() {
        let at = out.len() as u64;
        out[table + 8 * k..table + 8 * k + 8].copy_from_slice(&at.to_le_bytes());
        out.extend_from_slice(&(k as f32).to_le_bytes());
        out.extend_from_slice(&(lists.len() as i32).to_le_bytes());
        for &n in lists.iter() {
            out.extend_from_slice(&[1, 0]);
            out.extend_from_slice(&0.5f32.to_le_bytes());
            out.extend_from_slice(&[200, 100, 50, 255]);
            out.extend_from_slice(&(n as u64).to_le_bytes());
            for i in 0..n {
                for v in [i % 7, (i / 7) % 7, i / 49] {
                    out.extend_from_slice(&(v as f32 + 0.1 * k as f32).to_le_bytes());
                }
            }
        }
    }
    let end = out.len() as u64;
    out[table + 8 * frames.len()..table + 8 * frames.len() + 8].copy_from_slice(&end.to_le_bytes());
    out
}

/// A LAMMPS text dump of frames at timesteps 0, 100, 200 with `counts` atoms.
fn lammps_with_counts(dir: &Path, counts: [usize; 3]) -> PathBuf {
    let mut text = String::new();
    for (k, n) in counts.iter().enumerate() {
        text.push_str(&format!(
            "ITEM: TIMESTEP\n{}\nITEM: NUMBER OF ATOMS\n{n}\nITEM: BOX BOUNDS pp pp pp\n\
             0 10\n0 10\n0 10\nITEM: ATOMS id type x y z\n",
            100 * k
        ));
        for i in 0..*n {
            text.push_str(&format!("{} 1 {} {} 1\n", i + 1, i % 9, i / 9));
        }
    }
    let p = dir.join("thresh.dump");
    std::fs::write(&p, text).unwrap();
    p
}

/// A frame without particles cannot be a `.mdlod` file: a batch leaves it out (not
/// written, not listed, not expected of its shard), reports it with its input, frame and
/// timestep, and does the same on every rerun without trying to convert it; shards merge.
#[test]
fn an_empty_frame_is_skipped_reported_and_left_out_of_the_manifest() {
    use mdlod_preprocess::batch::EmptyFrame;
    let dir = tempfile::tempdir().unwrap();
    let src = lammps_with_counts(dir.path(), [30, 0, 20]);
    let out = dir.path().join("out");
    let empty = vec![EmptyFrame {
        input: src.clone(),
        frame: 1,
        timestep: Some(100),
        number: 100,
    }];
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!(
        (r.frames_total, r.frames_in_shard, r.converted, r.skipped),
        (3, 3, 2, 0)
    );
    assert_eq!(r.empty, empty);
    assert_eq!(
        empty[0].to_string(),
        format!(
            "{}: frame 1 (timestep 100) has no particles: skipped, as a .mdlod file needs at \
             least one (not written; listed as empty in the manifest)",
            src.display()
        )
    );
    let m = read_manifest(&out).unwrap();
    assert_eq!(
        m.frames.iter().map(|f| f.timestep).collect::<Vec<_>>(),
        [0, 200]
    );
    assert_eq!(m.expected_frames, Some(2));
    // Listed apart, so that the trajectory's length is known.
    let listed_empty = vec![mdlod_preprocess::batch::EmptyEntry {
        timestep: 100,
        input: src.display().to_string(),
        frame: 1,
    }];
    assert_eq!(m.empty, listed_empty);
    check_manifest(&out, &m);
    assert!(!out.join("frame-100.mdlod").exists());
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped, r.empty.clone()), (0, 2, empty));
    // Shards: the one holding the empty frame expects one frame fewer; the merge goes
    // through.
    let sharded = dir.path().join("sharded");
    for i in 0..2 {
        batch(
            std::slice::from_ref(&src),
            &sharded,
            &shard(i, 2),
            &NoProgress,
        )
        .unwrap();
    }
    let merged = merge(&sharded).unwrap();
    assert_eq!(
        (merged.frames, merged.expected_frames, merged.empty),
        (m.frames, Some(2), listed_empty)
    );

    // An MMPLD frame with no lists: numbered by its position (MMPLD has no timesteps).
    let zl = dir.path().join("zerolists.mmpld");
    std::fs::write(&zl, mmpld(&[&[10, 5], &[], &[12]])).unwrap();
    let out = dir.path().join("zl");
    let r = batch(std::slice::from_ref(&zl), &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped), (2, 0));
    assert_eq!(
        r.empty,
        [EmptyFrame {
            input: zl.clone(),
            frame: 1,
            timestep: None,
            number: 1,
        }]
    );
    assert!(r.empty[0]
        .to_string()
        .contains("frame 1 (number 1 in the batch)"));
    let r = batch(std::slice::from_ref(&zl), &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped, r.empty.len()), (0, 2, 1));

    // A plain XYZ trajectory whose atom lines carry a fifth column, with an empty frame,
    // converted with that column as the attribute: the empty frame's header names no
    // such column (a plain XYZ frame's extra columns come from its first atom line), and
    // resolving the attribute there failed the whole batch.
    let xyz = dir.path().join("t.xyz");
    let atoms = |n: usize, t: usize| -> String {
        (0..n)
            .map(|i| format!("Cu {i}.0 {t}.5 0.25 {}.5\n", i + t))
            .collect()
    };
    std::fs::write(
        &xyz,
        format!(
            "3\nframe 0\n{}0\nframe 1\n2\nframe 2\n{}",
            atoms(3, 0),
            atoms(2, 2)
        ),
    )
    .unwrap();
    let out = dir.path().join("xyz");
    let mut with_column = opts();
    with_column.read.attribute = Some("col5".into());
    let r = batch(std::slice::from_ref(&xyz), &out, &with_column, &NoProgress).unwrap();
    assert_eq!((r.converted, r.empty.len()), (2, 1));
    let m = read_manifest(&out).unwrap();
    for f in &m.frames {
        let file = mdlod_format::MdlodFile::open(out.join(&f.file)).unwrap();
        let a = file.metadata().attribute.clone().unwrap();
        assert_eq!(a.name, "col5");
    }
}

/// A GSD chunk: name, type code, N, M, data.
type GsdChunk<'a> = (&'a str, u8, u64, u32, Vec<u8>);

/// A GSD file (layer 2.0) of frames given as chunks; a frame's missing chunks come from
/// frame 0.
fn gsd(frames: &[Vec<GsdChunk<'_>>]) -> Vec<u8> {
    let mut names: Vec<&str> = vec![];
    for f in frames {
        for c in f {
            if !names.contains(&c.0) {
                names.push(c.0);
            }
        }
    }
    let mut out = vec![0u8; 256];
    out[..8].copy_from_slice(&0x65DF_65DF_65DF_65DFu64.to_le_bytes());
    out[44..48].copy_from_slice(&(2u32 << 16).to_le_bytes());
    out[112..117].copy_from_slice(b"hoomd");
    let mut entries = vec![];
    for (k, f) in frames.iter().enumerate() {
        for c in f {
            let id = names.iter().position(|n| *n == c.0).unwrap() as u16;
            entries.push((k as u64, c.2, out.len() as u64, c.3, id, c.1));
            out.extend_from_slice(&c.4);
        }
    }
    let index_at = out.len() as u64;
    for e in &entries {
        out.extend_from_slice(&e.0.to_le_bytes());
        out.extend_from_slice(&e.1.to_le_bytes());
        out.extend_from_slice(&e.2.to_le_bytes());
        out.extend_from_slice(&e.3.to_le_bytes());
        out.extend_from_slice(&e.4.to_le_bytes());
        out.extend_from_slice(&[e.5, 0]);
    }
    let names_at = out.len() as u64;
    let mut list: Vec<u8> = names
        .iter()
        .flat_map(|n| [n.as_bytes(), b"\0"].concat())
        .collect();
    list.resize(list.len().div_ceil(64) * 64 + 64, 0);
    out.extend_from_slice(&list);
    out[8..16].copy_from_slice(&index_at.to_le_bytes());
    out[16..24].copy_from_slice(&(entries.len() as u64).to_le_bytes());
    out[24..32].copy_from_slice(&names_at.to_le_bytes());
    out[32..40].copy_from_slice(&(list.len() as u64 / 64).to_le_bytes());
    out
}

/// Frames without timesteps are numbered by their position in the whole list of inputs,
/// whatever the format: an MMPLD file set (each file numbers its frames from 0, and MMPLD
/// records no timestep) and GSD files that record no `configuration/step` batch like an
/// XYZ file set; GSD files with steps keep them.
#[test]
fn mmpld_and_gsd_file_sets_without_timesteps_are_numbered_by_position() {
    let dir = tempfile::tempdir().unwrap();
    let parts: Vec<PathBuf> = (1..=2)
        .map(|i| {
            let p = dir.path().join(format!("part{i}.mmpld"));
            std::fs::write(&p, mmpld(&[&[10], &[12, 3]])).unwrap();
            p
        })
        .collect();
    let out = dir.path().join("set.d");
    let r = batch(&parts, &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.frames_total, r.converted), (4, 4));
    let m = read_manifest(&out).unwrap();
    let listed: Vec<(u64, String, u64)> = m
        .frames
        .iter()
        .map(|f| (f.timestep, f.source.path.clone(), f.source.frame))
        .collect();
    let name = |i: usize| parts[i].display().to_string();
    assert_eq!(
        listed,
        [
            (0, name(0), 0),
            (1, name(0), 1),
            (2, name(1), 0),
            (3, name(1), 1)
        ]
    );
    // The files record no timestep either.
    let f = MdlodFile::open(out.join("frame-2.mdlod")).unwrap();
    assert_eq!(f.metadata().timestep, None);

    let positions: Vec<u8> = (0..12)
        .flat_map(|i| (i as f32 * 0.5).to_le_bytes())
        .collect();
    let frame = |step: Option<u64>| {
        let mut chunks = vec![
            ("particles/N", 3u8, 1u64, 1u32, 4u32.to_le_bytes().to_vec()),
            ("particles/position", 9, 4, 3, positions.clone()),
        ];
        if let Some(s) = step {
            chunks.push(("configuration/step", 4, 1, 1, s.to_le_bytes().to_vec()));
        }
        chunks
    };
    let no_steps: Vec<PathBuf> = (0..2)
        .map(|i| {
            let p = dir.path().join(format!("nostep{i}.gsd"));
            std::fs::write(&p, gsd(&[frame(None), frame(None)])).unwrap();
            p
        })
        .collect();
    let out = dir.path().join("nostep.d");
    let r = batch(&no_steps, &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.frames_total, r.converted), (4, 4));
    let m = read_manifest(&out).unwrap();
    assert_eq!(
        m.frames.iter().map(|f| f.timestep).collect::<Vec<_>>(),
        [0, 1, 2, 3]
    );
    // With steps (the second frame inherits none: it records its own), they number the
    // frames.
    let steps = dir.path().join("steps.gsd");
    std::fs::write(&steps, gsd(&[frame(Some(10)), frame(Some(20))])).unwrap();
    let out = dir.path().join("steps.d");
    batch(std::slice::from_ref(&steps), &out, &opts(), &NoProgress).unwrap();
    let m = read_manifest(&out).unwrap();
    assert_eq!(
        m.frames.iter().map(|f| f.timestep).collect::<Vec<_>>(),
        [10, 20]
    );
}

/// A trajectory whose particles of one type differ in size, differently in each frame
/// (particles growing): every frame keeps its particles' own radii, over its own range,
/// with nothing to note.
#[test]
fn differing_radii_are_kept_per_particle_in_every_frame_of_a_trajectory() {
    let dir = tempfile::tempdir().unwrap();
    let positions: Vec<u8> = (0..12)
        .flat_map(|i| (i as f32 * 0.5).to_le_bytes())
        .collect();
    let frame = |step: u64| {
        let diameters: Vec<u8> = (0..4)
            .flat_map(|i| (1.0 + (i * step) as f32).to_le_bytes())
            .collect();
        vec![
            ("particles/N", 3u8, 1u64, 1u32, 4u32.to_le_bytes().to_vec()),
            ("particles/position", 9, 4, 3, positions.clone()),
            ("particles/diameter", 9, 4, 1, diameters),
            ("configuration/step", 4, 1, 1, step.to_le_bytes().to_vec()),
            // (A box holding them: the schema's default box of 1 would not.)
            (
                "configuration/box",
                9,
                6,
                1,
                [20.0f32, 20.0, 20.0, 0.0, 0.0, 0.0]
                    .iter()
                    .flat_map(|v| v.to_le_bytes())
                    .collect(),
            ),
        ]
    };
    let src = dir.path().join("grow.gsd");
    std::fs::write(&src, gsd(&[frame(1), frame(2), frame(3)])).unwrap();
    let r = batch(
        std::slice::from_ref(&src),
        &dir.path().join("grow.d"),
        &opts(),
        &NoProgress,
    )
    .unwrap();
    assert_eq!(r.converted, 3);
    assert_eq!(r.notes, Vec::<String>::new());
    for step in 1..=3u64 {
        let f = mdlod_format::MdlodFile::open(
            dir.path()
                .join("grow.d")
                .join(format!("frame-{step}.mdlod")),
        )
        .unwrap();
        let info = f.metadata().radius.expect("per-particle radii");
        assert_eq!((info.min, info.max), (0.5, 0.5 + 1.5 * step as f32));
        let mut radii: Vec<f32> = (0..4).map(|i| f.particle_radius(i)).collect();
        radii.sort_by(f32::total_cmp);
        let want: Vec<f32> = (0..4).map(|i| 0.5 + 0.5 * (i * step) as f32).collect();
        for (r, w) in radii.iter().zip(&want) {
            assert!((r - w).abs() <= 1e-4, "{radii:?} against {want:?}");
        }
    }
}

/// A rerun learns which `--radius` overrides built a frame from the manifest, not by
/// reading the input again (a GSD frame's every diameter, for every frame of a long
/// trajectory): an input whose diameters changed in place, its size and time kept, is
/// not read, while leaving out an override still rebuilds.
#[test]
fn a_rerun_compares_the_recorded_overrides_without_reading_the_input() {
    let dir = tempfile::tempdir().unwrap();
    let positions: Vec<u8> = (0..12)
        .flat_map(|i| (i as f32 * 0.5).to_le_bytes())
        .collect();
    let gsd_with = |d: f32| {
        gsd(&[vec![
            ("particles/N", 3u8, 1u64, 1u32, 4u32.to_le_bytes().to_vec()),
            ("particles/position", 9, 4, 3, positions.clone()),
            (
                "particles/diameter",
                9,
                4,
                1,
                (0..4).flat_map(|_| d.to_le_bytes()).collect(),
            ),
        ]])
    };
    let src = dir.path().join("d.gsd");
    std::fs::write(&src, gsd_with(2.0)).unwrap();
    let out = dir.path().join("d.d");
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!(r.converted, 1);
    let m = read_manifest(&out).unwrap();
    assert_eq!(m.frames[0].radii, Some(vec![]));
    // Diameters 3 instead of 2, the file's size and time as before.
    let time = std::fs::metadata(&src).unwrap().modified().unwrap();
    std::fs::write(&src, gsd_with(3.0)).unwrap();
    std::fs::File::options()
        .write(true)
        .open(&src)
        .unwrap()
        .set_modified(time)
        .unwrap();
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped), (0, 1), "the input was read again");
    // An override is recorded, and leaving it out again rebuilds with the input's own.
    let mut with = opts();
    with.convert.radii = vec![("A".into(), 0.7)];
    let r = batch(std::slice::from_ref(&src), &out, &with, &NoProgress).unwrap();
    assert_eq!(r.converted, 1);
    let m = read_manifest(&out).unwrap();
    assert_eq!(m.frames[0].radii, Some(vec![("A".to_string(), 0.7)]));
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!(r.converted, 1);
    let f = MdlodFile::open(out.join(&read_manifest(&out).unwrap().frames[0].file)).unwrap();
    assert_eq!(f.metadata().species[0].radius, 1.5);
}

#[test]
fn merge_refuses_shards_built_with_other_settings() {
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let species = {
        let out = dir.path().join("probe");
        let m = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
        let f = MdlodFile::open(out.join(&read_manifest(&out).unwrap().frames[0].file)).unwrap();
        assert!(m.frames_total > 0);
        f.metadata().species[0].clone()
    };
    // Shard 1 with another precision, then with a radius override.
    let precision = |o: &mut BatchOptions| o.convert.build.position_bits = 8;
    let radius = |o: &mut BatchOptions| {
        o.convert.radii = vec![(species.name.clone(), species.radius * 2.0)];
    };
    type Change<'a> = &'a dyn Fn(&mut BatchOptions);
    let cases: [(Change, &str); 2] = [
        (&precision, "position bits 16"),
        (&radius, &format!("radius of species {}", species.name)),
    ];
    for (k, (change, setting)) in cases.iter().enumerate() {
        let out = dir.path().join(format!("d{k}"));
        batch(std::slice::from_ref(&src), &out, &shard(0, 2), &NoProgress).unwrap();
        let mut o = shard(1, 2);
        change(&mut o);
        batch(std::slice::from_ref(&src), &out, &o, &NoProgress).unwrap();
        let v = mdlod_preprocess::batch::verify_dir(&out, &NoProgress).unwrap();
        assert!(
            v.problems
                .iter()
                .any(|p| p.contains("the shards would not merge") && p.contains(setting)),
            "{setting}: {:?}",
            v.problems
        );
        let e = merge(&out).unwrap_err().to_string();
        assert!(
            e.contains("different settings")
                && e.contains(setting)
                && e.contains("dataset.shard-0-of-2.json")
                && e.contains("dataset.shard-1-of-2.json"),
            "{e}"
        );
        assert!(!out.join("dataset.json").exists());
        // Shard 1 rerun with the same options as shard 0: the merge goes through.
        batch(std::slice::from_ref(&src), &out, &shard(1, 2), &NoProgress).unwrap();
        assert_eq!(merge(&out).unwrap().frames.len(), 6);
    }
}

/// After a merge, the input changes and one shard runs again: it removes the merged
/// manifest, whose checksums it outdates, and the merge then refuses to join frames of
/// the two versions of the input until the other shards have run again.
#[test]
fn a_shard_rerun_after_a_merge_outdates_it_and_merge_refuses_mixed_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let out = dir.path().join("sharded");
    for i in 0..2 {
        batch(std::slice::from_ref(&src), &out, &shard(i, 2), &NoProgress).unwrap();
    }
    merge(&out).unwrap();
    // Nothing to convert: the merged manifest stays.
    let r = batch(std::slice::from_ref(&src), &out, &shard(1, 2), &NoProgress).unwrap();
    assert_eq!((r.converted, r.removed_merged), (0, None));
    assert!(read_manifest(&out).is_ok());
    // The input changes (one more line at its end: a new size, and the last frame's
    // bytes); shard 1 converts that frame again and keeps its other two.
    let mut text = std::fs::read(&src).unwrap();
    text.extend_from_slice(b"\n");
    std::fs::write(&src, &text).unwrap();
    let r = batch(std::slice::from_ref(&src), &out, &shard(1, 2), &NoProgress).unwrap();
    assert_eq!((r.converted, r.kept_unchanged), (1, 2));
    assert_eq!(r.removed_merged, Some(out.join("dataset.json")));
    assert!(!out.join("dataset.json").exists());
    let e = merge(&out).unwrap_err().to_string();
    assert!(
        e.contains("two versions of") && e.contains("melt.dump") && e.contains("rerun the shards"),
        "{e}"
    );
    batch(std::slice::from_ref(&src), &out, &shard(0, 2), &NoProgress).unwrap();
    check_manifest(&out, &merge(&out).unwrap());
}

/// Frame files of an earlier run over a longer trajectory are named, not listed, and
/// left alone.
#[test]
fn frame_files_of_no_input_frame_are_reported() {
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let out = dir.path().join("out");
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert!(r.strays.is_empty());
    for name in [
        "frame-99000.mdlod",
        "frame-7.mdlod",
        "frame-07.mdlod",
        "notes.txt",
    ] {
        std::fs::write(out.join(name), b"x").unwrap();
    }
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    // `frame-07.mdlod` is no frame's name (frame 7 is `frame-7.mdlod`).
    assert_eq!(r.strays, ["frame-7.mdlod", "frame-99000.mdlod"]);
    assert_eq!(r.skipped, 6);
    assert!(out.join("frame-99000.mdlod").exists());
}

/// The same input named by another path (from another directory, as a requeued job
/// does) is the same source: nothing converts again. Another file of the same name,
/// size and time would be too; one of another time has its frames' bytes compared, and
/// only those that differ convert again.
#[test]
fn the_same_input_by_another_path_is_not_converted_again() {
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let out = dir.path().join("out");
    batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    std::fs::create_dir(dir.path().join("sub")).unwrap();
    let other = dir.path().join("sub").join("..").join("melt.dump");
    let r = batch(&[other], &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped), (0, 6));
    // A copy elsewhere, written now: another modification time, the same bytes.
    let copy = dir.path().join("sub").join("melt.dump");
    std::fs::copy(&src, &copy).unwrap();
    let r = batch(std::slice::from_ref(&copy), &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.kept_unchanged), (0, 6));
    // Another run's dump of the same name: its last frame differs.
    let mut text = std::fs::read(&src).unwrap();
    let at = text.len() - 20;
    let digit = (at..text.len())
        .find(|&i| text[i].is_ascii_digit() && text[i] != b'9')
        .unwrap();
    text[digit] += 1;
    std::fs::write(&copy, &text).unwrap();
    let r = batch(&[copy], &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.kept_unchanged, r.redone.source), (1, 5, 1));
}

/// A frame changed in place (a digit more in one atom's line) moves every later frame's
/// bytes: those are the same bytes elsewhere, kept as README says ("kept when its own
/// bytes are unchanged"), and listed at their new place so that the next run keeps them
/// without reading them; they were all converted again.
#[test]
fn frames_whose_bytes_only_moved_are_kept() {
    use mdlod_preprocess::readers::DumpFile;
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let out = dir.path().join("out");
    batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    let mut text = std::fs::read(&src).unwrap();
    let second = DumpFile::open(&src).unwrap().frame_bytes(1).unwrap();
    // A coordinate of frame 1 written with one more digit: `... 1.5 ...` as `1.50`.
    let last_line = text[..second.end as usize - 1]
        .iter()
        .rposition(|&b| b == b'\n')
        .unwrap();
    let end_of_line = second.end as usize - 1;
    assert!(end_of_line > last_line + 1);
    text.insert(end_of_line, b'0');
    std::fs::write(&src, &text).unwrap();
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.kept_unchanged, r.redone.source), (1, 5, 1));
    let m = read_manifest(&out).unwrap();
    check_manifest(&out, &m);
    let moved = DumpFile::open(&src).unwrap().frame_bytes(4).unwrap();
    let listed = m.frames[4].source.bytes.clone().unwrap();
    assert_eq!((listed.start, listed.end), (moved.start, moved.end));
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped, r.kept_unchanged), (0, 6, 0));
}

/// The real dump's first frame once for each of `steps`, as that timestep: a text dump
/// of the timesteps a test needs (restarts, twins).
fn first_frame_at(steps: &[u64]) -> String {
    let text = std::fs::read_to_string(lammps_sample_path("cu_melt.custom.dump")).unwrap();
    // Its frames begin `ITEM: TIME`, then `ITEM: TIMESTEP`.
    let start = text.find("ITEM: TIMESTEP").unwrap();
    let end = start + text[start..].find("ITEM: TIME\n").unwrap();
    let first_frame = &text[start..end];
    let step_line = first_frame.lines().nth(1).unwrap();
    let mut dump = String::new();
    for t in steps {
        dump.push_str(&first_frame.replacen(
            &format!("ITEM: TIMESTEP\n{step_line}\n"),
            &format!("ITEM: TIMESTEP\n{t}\n"),
            1,
        ));
    }
    dump
}

/// A run restarted into the same dump repeats timesteps: refused by default with the
/// way out named; with `Last` the later frame of each converts (its source frame is
/// recorded), with `First` the earlier; the others are reported.
#[test]
fn duplicate_timesteps_are_refused_or_resolved_as_asked() {
    use mdlod_preprocess::batch::Duplicates;
    let dir = tempfile::tempdir().unwrap();
    // The real dump's first frame four times, as timesteps 0, 100, 100, 200.
    let src = dir.path().join("restarted.dump");
    std::fs::write(&src, first_frame_at(&[0, 100, 100, 200])).unwrap();
    let e = batch(
        std::slice::from_ref(&src),
        &dir.path().join("e"),
        &opts(),
        &NoProgress,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("timestep 100 appears twice") && e.contains("--duplicate-timesteps last"),
        "{e}"
    );
    for (policy, frame) in [(Duplicates::Last, 2), (Duplicates::First, 1)] {
        let out = dir.path().join(format!("{policy:?}"));
        let o = BatchOptions {
            duplicates: policy,
            ..opts()
        };
        let r = batch(std::slice::from_ref(&src), &out, &o, &NoProgress).unwrap();
        assert_eq!((r.frames_total, r.converted), (3, 3));
        assert_eq!(r.duplicates.len(), 1, "{:?}", r.duplicates);
        let m = read_manifest(&out).unwrap();
        let hundred = m.frames.iter().find(|f| f.timestep == 100).unwrap();
        assert_eq!(hundred.source.frame, frame, "{policy:?}");
        assert!(
            r.duplicates[0].contains(&format!("frame {frame} converted")),
            "{:?}",
            r.duplicates
        );
    }
    // A restart supersedes every earlier frame from its timestep on, twin or not: the
    // abandoned run's 300 and 400 are left out after a restart at 200 that reached 250.
    let src = dir.path().join("restarted-short.dump");
    std::fs::write(&src, first_frame_at(&[0, 100, 200, 300, 400, 200, 250])).unwrap();
    let out = dir.path().join("restart");
    let o = BatchOptions {
        duplicates: Duplicates::Last,
        ..opts()
    };
    let r = batch(std::slice::from_ref(&src), &out, &o, &NoProgress).unwrap();
    let m = read_manifest(&out).unwrap();
    let kept: Vec<(u64, u64)> = m
        .frames
        .iter()
        .map(|f| (f.timestep, f.source.frame))
        .collect();
    assert_eq!(kept, [(0, 0), (100, 1), (200, 5), (250, 6)]);
    assert_eq!(r.duplicates.len(), 3, "{:?}", r.duplicates);
    assert!(
        r.duplicates.iter().any(|d| d.contains("timestep 400")
            && d.contains("superseded by the restart at timestep 200")),
        "{:?}",
        r.duplicates
    );
}

/// A restart from a timestep between two the first run wrote shares no timestep with
/// it, so no frame appears twice, yet the two runs' frames would interleave (800, 850,
/// 900, 950, ... flipping between runs): refused by default, in one dump and across two,
/// naming the frames; `last` keeps the restart's frames from its first timestep on,
/// `first` every frame. Inputs that merely follow one another are no restart, in
/// whatever order their names give.
#[test]
fn runs_whose_frames_would_interleave_are_refused_by_default() {
    use mdlod_preprocess::batch::Duplicates;
    let dir = tempfile::tempdir().unwrap();
    let dump = |name: &str, steps: &[u64]| {
        let p = dir.path().join(name);
        std::fs::write(&p, first_frame_at(steps)).unwrap();
        p
    };
    let first = dump("run.1.dump", &[0, 100, 200, 300]);
    let restart = dump("run.2.dump", &[150, 250, 350]);
    let one = dump("one.dump", &[0, 100, 200, 300, 150, 250, 350]);
    let refused = |inputs: &[PathBuf], says: &str, last: &str| {
        let e = batch(inputs, &dir.path().join("e"), &opts(), &NoProgress)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("the frames of two runs would interleave")
                && e.contains(says)
                && e.contains(&format!("--duplicate-timesteps last keeps {last}")),
            "{e}"
        );
    };
    // (`last` takes the inputs in their order: the later one's frames win.)
    refused(
        &[first.clone(), restart.clone()],
        "run.2.dump frame 0 at timestep 150 falls before ",
        "the frames of ",
    );
    refused(
        &[first.clone(), restart.clone()],
        "run.2.dump, the later input in their order (their paths' natural order), from its \
         first timestep 150 on, leaving out those of ",
        "",
    );
    refused(
        std::slice::from_ref(&one),
        "one.dump frame 4 at timestep 150 follows ",
        "the restart's frames (from timestep 150 on",
    );
    for (policy, kept) in [
        (Duplicates::Last, vec![0, 100, 150, 250, 350]),
        (Duplicates::First, vec![0, 100, 150, 200, 250, 300, 350]),
    ] {
        let o = BatchOptions {
            duplicates: policy,
            ..opts()
        };
        let out = dir.path().join(format!("{policy:?}"));
        batch(&[first.clone(), restart.clone()], &out, &o, &NoProgress).unwrap();
        let m = read_manifest(&out).unwrap();
        let steps: Vec<u64> = m.frames.iter().map(|f| f.timestep).collect();
        assert_eq!(steps, kept, "{policy:?}");
    }
    // Runs that follow one another, named against their order: converted.
    let later = dump("a.dump", &[400, 500]);
    let r = batch(
        &[later, first],
        &dir.path().join("ok"),
        &opts(),
        &NoProgress,
    )
    .unwrap();
    assert_eq!(r.converted, 6);
}

/// A dump written again under its name keeps listed only the frames of the earlier run
/// before the first timestep it holds now (a restart from 300 into the same file name
/// keeps 0 to 200); its frames from there on, and a restart's superseded frames
/// (`--duplicate-timesteps last`), are named as frame files of no input, not listed as
/// frames of a gone dump (which `verify` then passed, and a movie showed after the
/// restart's).
#[test]
fn frames_a_rewritten_or_restarted_dump_no_longer_holds_are_not_listed() {
    use mdlod_preprocess::batch::Duplicates;
    let dir = tempfile::tempdir().unwrap();
    let frames = first_frame_at;
    let src = dir.path().join("run.dump");
    for (case, again, policy, want) in [
        // Written again, shorter: 400 and 500 are the old run's, not this one's.
        (
            "shorter",
            frames(&[0, 100, 200, 300]),
            Duplicates::Error,
            vec![0, 100, 200, 300],
        ),
        // A restart from 300 into the same name: 0 to 200 are the earlier run's alone.
        (
            "restart",
            frames(&[300, 400]),
            Duplicates::Error,
            vec![0, 100, 200, 300, 400],
        ),
        // A restart from 200 appended: 400 and 500 superseded.
        (
            "appended",
            frames(&[0, 100, 200, 300, 400, 500, 200, 300]),
            Duplicates::Last,
            vec![0, 100, 200, 300],
        ),
    ] {
        let out = dir.path().join(case);
        std::fs::write(&src, frames(&[0, 100, 200, 300, 400, 500])).unwrap();
        batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
        // (Another modification time than the first version's.)
        std::thread::sleep(std::time::Duration::from_millis(20));
        std::fs::write(&src, again).unwrap();
        let o = BatchOptions {
            duplicates: policy,
            ..opts()
        };
        batch(std::slice::from_ref(&src), &out, &o, &NoProgress).unwrap();
        assert_eq!(listed(&out), want, "{case}");
        check_manifest(&out, &read_manifest(&out).unwrap());
    }
}

/// A batch directory is verified against its manifest: every listed frame there, whole
/// and the one described; what is missing, replaced or unlisted is named; shards not
/// yet merged are checked through their own manifests.
#[test]
fn a_batch_directory_verifies_against_its_manifest() {
    use mdlod_preprocess::batch::verify_dir;
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let out = dir.path().join("out");
    batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    let c = verify_dir(&out, &NoProgress).unwrap();
    assert_eq!((c.frames_ok, c.problems.len()), (6, 0), "{c:?}");
    assert_eq!(c.manifests, ["dataset.json"]);
    let m = read_manifest(&out).unwrap();
    let (a, b) = (&m.frames[1].file, &m.frames[2].file);
    std::fs::copy(out.join(b), out.join(a)).unwrap();
    std::fs::remove_file(out.join(&m.frames[3].file)).unwrap();
    std::fs::copy(out.join(b), out.join("frame-99.mdlod")).unwrap();
    let c = verify_dir(&out, &NoProgress).unwrap();
    assert_eq!(c.frames_ok, 4, "{c:?}");
    assert_eq!(c.problems.len(), 2, "{c:?}");
    assert!(c
        .problems
        .iter()
        .any(|p| p.starts_with(a.as_str()) && p.contains("checksum")));
    assert!(c
        .problems
        .iter()
        .any(|p| p.starts_with(m.frames[3].file.as_str()) && p.contains("listed but missing")));
    assert_eq!(c.unlisted, ["frame-99.mdlod"]);
    // A manifest entry of other particles: the file's timestep named as a number.
    let mut wrong = read_manifest(&out).unwrap();
    wrong.frames[0].particles += 1;
    std::fs::write(
        out.join("dataset.json"),
        serde_json::to_vec(&wrong).unwrap(),
    )
    .unwrap();
    let c = verify_dir(&out, &NoProgress).unwrap();
    let want = format!(
        "the file holds timestep 0 and {} particles, the manifest says timestep 0 and {} \
         particles",
        m.frames[0].particles,
        m.frames[0].particles + 1
    );
    assert!(c.problems.iter().any(|p| p.ends_with(&want)), "{c:?}");
    // Frames listed out of timestep order, or a timestep twice: named.
    let mut reversed = read_manifest(&out).unwrap();
    // (The particle count put right again, so that only the order is wrong.)
    reversed.frames[0].particles -= 1;
    reversed.frames.reverse();
    std::fs::write(
        out.join("dataset.json"),
        serde_json::to_vec(&reversed).unwrap(),
    )
    .unwrap();
    let c = verify_dir(&out, &NoProgress).unwrap();
    let (first, second) = (&reversed.frames[0], &reversed.frames[1]);
    let want = format!(
        "dataset.json does not list its frames by timestep: {} (timestep {}) follows {} \
         (timestep {})",
        second.file, second.timestep, first.file, first.timestep
    );
    assert!(c.problems.contains(&want), "{c:?}");
    let mut twice = read_manifest(&out).unwrap();
    twice.frames.reverse();
    twice.frames[1] = twice.frames[0].clone();
    std::fs::write(
        out.join("dataset.json"),
        serde_json::to_vec(&twice).unwrap(),
    )
    .unwrap();
    let c = verify_dir(&out, &NoProgress).unwrap();
    let f = &twice.frames[0];
    let want = format!(
        "dataset.json lists timestep {} twice ({} and {})",
        f.timestep, f.file, f.file
    );
    assert!(c.problems.contains(&want), "{c:?}");
    // Shards, not merged: checked through their manifests.
    let sharded = dir.path().join("sharded");
    for i in 0..2 {
        batch(
            std::slice::from_ref(&src),
            &sharded,
            &shard(i, 2),
            &NoProgress,
        )
        .unwrap();
    }
    let c = verify_dir(&sharded, &NoProgress).unwrap();
    assert_eq!((c.frames_ok, c.problems.len()), (6, 0), "{c:?}");
    assert_eq!(c.manifests.len(), 2);
    // A shard that never ran is a problem, though every frame listed verifies.
    std::fs::remove_file(sharded.join("dataset.shard-1-of-2.json")).unwrap();
    let c = verify_dir(&sharded, &NoProgress).unwrap();
    assert_eq!(c.frames_ok, 3);
    assert!(
        c.problems.len() == 1 && c.problems[0].contains("shard 1 of 2 wrote no manifest"),
        "{c:?}"
    );
    // No merge while a shard still writes the directory (it holds the batch lock
    // shared): busy, as a whole run beside it is.
    {
        let lock = std::fs::File::open(sharded.join(".batch.lock")).unwrap();
        lock.try_lock_shared().unwrap();
        let e = merge(&sharded).unwrap_err();
        assert!(matches!(e, BatchError::Busy { .. }), "{e}");
        // A shard's manifest short of its frames while it runs: said as running, not
        // as a run to rerun.
        let zero = sharded.join("dataset.shard-0-of-2.json");
        let mut v: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&zero).unwrap()).unwrap();
        v["expected_frames"] = 4.into();
        std::fs::write(&zero, serde_json::to_vec(&v).unwrap()).unwrap();
        let c = verify_dir(&sharded, &NoProgress).unwrap();
        assert!(
            c.problems.iter().any(|p| p.contains(
                "lists 3 of the 4 frames its run expects: a batch is writing the directory now \
                 (shards of a batch)"
            )),
            "{c:?}"
        );
        drop(lock);
        let c = verify_dir(&sharded, &NoProgress).unwrap();
        assert!(
            c.problems
                .iter()
                .any(|p| p.contains("4 frames its run expects: that run has not finished")),
            "{c:?}"
        );
    }
    // Two shardings side by side (a task resubmitted alone as shard 0 of 1 beside the
    // two shards): each frame file is verified and counted once, not once per manifest
    // listing it.
    let two = dir.path().join("two-shardings");
    for (i, n) in [(0, 2), (1, 2), (0, 1)] {
        batch(std::slice::from_ref(&src), &two, &shard(i, n), &NoProgress).unwrap();
    }
    let c = verify_dir(&two, &NoProgress).unwrap();
    assert_eq!((c.frames_ok, c.manifests.len()), (6, 3), "{c:?}");
    assert!(
        c.problems.len() == 1 && c.problems[0].contains("of 1") && c.problems[0].contains("of 2"),
        "{c:?}"
    );
    // A frame replaced after one manifest was written is named against each listing.
    let mut v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(two.join("dataset.shard-0-of-1.json")).unwrap())
            .unwrap();
    let first = v["frames"][0]["file"].as_str().unwrap().to_string();
    v["frames"][0]["checksum"] = "0000000000000000".into();
    std::fs::write(
        two.join("dataset.shard-0-of-1.json"),
        serde_json::to_vec(&v).unwrap(),
    )
    .unwrap();
    let c = verify_dir(&two, &NoProgress).unwrap();
    assert_eq!(c.frames_ok, 5, "{c:?}");
    let named: Vec<&String> = c
        .problems
        .iter()
        .filter(|p| p.starts_with(&first))
        .collect();
    assert!(
        named.len() == 1 && named[0].contains("in dataset.shard-0-of-1.json"),
        "{c:?}"
    );
    assert!(verify_dir(&dir.path().join("nothing-here"), &NoProgress).is_err());
}

/// A raw sidecar's arrays are its data: new positions behind an unchanged sidecar are
/// converted again (the rerun kept the old frame, its manifest entry checked out).
#[test]
fn new_raw_arrays_behind_an_unchanged_sidecar_are_converted_again() {
    let dir = tempfile::tempdir().unwrap();
    let write_positions = |offset: f32| {
        let pos: Vec<u8> = (0..300)
            .flat_map(|i| [i as f32 + offset, (i % 7) as f32, (i % 11) as f32])
            .flat_map(f32::to_le_bytes)
            .collect();
        std::fs::write(dir.path().join("pos.f32"), pos).unwrap();
    };
    write_positions(0.0);
    let sidecar = dir.path().join("snap.raw.json");
    std::fs::write(
        &sidecar,
        r#"{"mdlod_raw": 1, "positions": {"file": "pos.f32", "type": "f32"}, "timestep": 5}"#,
    )
    .unwrap();
    let out = dir.path().join("out");
    let r = batch(std::slice::from_ref(&sidecar), &out, &opts(), &NoProgress).unwrap();
    assert_eq!(r.converted, 1);
    let before = read_manifest(&out).unwrap().frames[0].checksum.clone();
    // The same length, other values: only the array changed.
    write_positions(0.5);
    let r = batch(std::slice::from_ref(&sidecar), &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped), (1, 0));
    assert_ne!(read_manifest(&out).unwrap().frames[0].checksum, before);
}

/// The dump a running simulation is still writing: a rerun over it once it has grown
/// converts only the new frames (the old ones' bytes are read and compared once), the
/// next rerun reads nothing, and a frame whose bytes changed is converted again. In each
/// format whose frames are byte ranges: LAMMPS text and binary dumps, XYZ files.
#[test]
fn a_dump_that_grows_converts_only_its_new_frames() {
    use mdlod_preprocess::readers::DumpFile;
    for name in ["cu_melt.custom.dump", "cu_melt.custom.bin", "cu_melt.xyz"] {
        let dir = tempfile::tempdir().unwrap();
        let whole = std::fs::read(lammps_sample_path(name)).unwrap();
        let frames = DumpFile::open(&lammps_sample_path(name)).unwrap();
        let count = frames.frame_count();
        assert!(count >= 3, "{name}: {count} frames");
        let end_of = |k: usize| frames.frame_bytes(k).unwrap().end as usize;
        let src = dir.path().join(name);
        let out = dir.path().join("out");
        // Two frames written so far.
        std::fs::write(&src, &whole[..end_of(1)]).unwrap();
        let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
        assert_eq!((r.converted, r.skipped), (2, 0), "{name}");
        let first = read_manifest(&out).unwrap();
        let start_of_2 = frames.frame_bytes(2).unwrap().start as usize;
        assert_eq!(start_of_2, end_of(1), "{name}: frames are adjacent");

        // The rest appended.
        std::fs::write(&src, &whole).unwrap();
        let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
        assert_eq!(
            (r.converted, r.skipped, r.kept_unchanged, r.redone.source),
            (count - 2, 2, 2, 0),
            "{name}"
        );
        let grown = read_manifest(&out).unwrap();
        assert_eq!(grown.frames.len(), count);
        for (a, b) in first.frames.iter().zip(&grown.frames) {
            assert_eq!(
                (&a.file, &a.checksum),
                (&b.file, &b.checksum),
                "{name}: kept as is"
            );
            // Listed with the input as it is now, so that the next rerun reads nothing.
            assert_eq!(b.source.size, whole.len() as u64);
            assert_eq!(a.source.bytes, b.source.bytes);
        }
        check_manifest(&out, &grown);

        let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
        assert_eq!(
            (r.converted, r.skipped, r.kept_unchanged),
            (0, count, 0),
            "{name}"
        );

        // Touched, and one frame's bytes changed: that frame alone is converted again.
        if name.ends_with(".bin") {
            continue;
        }
        let range = frames.frame_bytes(1).unwrap();
        let mut changed = whole.clone();
        let middle = (range.start + range.end) as usize / 2;
        let digit = (middle..range.end as usize)
            .find(|&i| changed[i].is_ascii_digit() && changed[i] != b'9')
            .unwrap();
        changed[digit] += 1;
        std::fs::write(&src, &changed).unwrap();
        let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
        assert_eq!(
            (r.converted, r.kept_unchanged, r.redone.source),
            (1, count - 1, 1),
            "{name}"
        );
        let after = read_manifest(&out).unwrap();
        assert_ne!(after.frames[1].checksum, grown.frames[1].checksum, "{name}");
        check_manifest(&out, &after);
    }
}

/// A frame being written when the batch runs is left for the rerun, which keeps the
/// frames before it by their bytes.
#[test]
fn a_frame_cut_short_while_written_is_converted_by_the_rerun() {
    use mdlod_preprocess::readers::DumpFile;
    let dir = tempfile::tempdir().unwrap();
    let name = "cu_melt.custom.dump";
    let whole = std::fs::read(lammps_sample_path(name)).unwrap();
    let frames = DumpFile::open(&lammps_sample_path(name)).unwrap();
    let third = frames.frame_bytes(2).unwrap();
    let src = dir.path().join(name);
    let out = dir.path().join("out");
    std::fs::write(&src, &whole[..(third.start + third.end) as usize / 2]).unwrap();
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.incomplete.len()), (2, 1));
    std::fs::write(&src, &whole).unwrap();
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!(
        (r.converted, r.kept_unchanged, r.incomplete.len()),
        (frames.frame_count() - 2, 2, 0)
    );
    check_manifest(&out, &read_manifest(&out).unwrap());
}

/// Wherever a run still writing its dump stops, in its last frame's header or its data,
/// in text, XYZ and binary dumps alike: the frames before it convert, the cut one is
/// left for the rerun with a note, and the directory verifies.
#[test]
fn a_dump_cut_anywhere_in_its_last_frame_converts_the_frames_before() {
    use mdlod_preprocess::readers::DumpFile;
    for name in ["cu_melt.custom.dump", "cu_melt.xyz", "cu_melt.custom.bin"] {
        let whole = std::fs::read(lammps_sample_path(name)).unwrap();
        let frames = DumpFile::open(&lammps_sample_path(name)).unwrap();
        let third = frames.frame_bytes(2).unwrap();
        let (start, end) = (third.start as usize, third.end as usize);
        // Cuts in the header's first bytes and lines, and in the atoms' data.
        let mut cuts: Vec<usize> = vec![start + 1, start + 7, (start + end) / 2, end - 3];
        if !name.ends_with(".bin") {
            // After each of the header's first lines (`ITEM: TIMESTEP`, its value, ...),
            // and one and six bytes into the next (`I`, `ITEM: `: the next header line of
            // the frame, not a new frame).
            let lines = whole[start..end]
                .iter()
                .enumerate()
                .filter(|(_, &b)| b == b'\n')
                .map(|(i, _)| start + i + 1)
                .take(9)
                .flat_map(|b| [b, b + 1, b + 6])
                .filter(|&c| c < end);
            cuts.extend(lines);
        } else {
            cuts.extend([start + 8, start + 40, start + 100]);
        }
        for cut in cuts {
            let dir = tempfile::tempdir().unwrap();
            let src = dir.path().join(name);
            let out = dir.path().join("out");
            std::fs::write(&src, &whole[..cut]).unwrap();
            let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress)
                .unwrap_or_else(|e| panic!("{name} cut at byte {cut}: {e}"));
            assert_eq!(
                (r.converted, r.incomplete.len()),
                (2, 1),
                "{name} cut at byte {cut} ({} into its third frame)",
                cut - start
            );
            let m = read_manifest(&out).unwrap();
            assert_eq!((m.frames.len(), m.expected_frames), (2, Some(2)));
            check_manifest(&out, &m);
        }
    }
}

/// The same for a `%` set whose last frame one piece holds only in part, binary or text,
/// wherever the cut falls (the magic string, the timestep, the box, the chunk data; a
/// text header's lines, the atoms): the frames every piece holds whole convert, the cut
/// one is left for the rerun with a note naming the piece, which converts it once
/// complete.
#[test]
fn a_piece_set_cut_anywhere_in_its_last_frame_converts_the_frames_before() {
    use mdlod_preprocess::readers::DumpFile;
    // Bytes from frame 2's start: binary, the magic string's length and text, the
    // timestep (at 26), the box (at 70), the chunk data (from 153); text, `ITEM:`, the
    // timestep's line cut, whole, and the next, the box, the atoms.
    let binary_cuts: &[usize] = &[4, 12, 29, 75, 160, 6000];
    let text_cuts: &[usize] = &[5, 15, 17, 19, 30, 120, 400];
    for (ext, cuts) in [("bin", binary_cuts), ("dump", text_cuts)] {
        let whole: Vec<Vec<u8>> = (0..2)
            .map(|k| std::fs::read(lammps_sample_path(&format!("cu_melt_mpi.{k}.{ext}"))).unwrap())
            .collect();
        for cut_piece in 0..2 {
            let source = lammps_sample_path(&format!("cu_melt_mpi.{cut_piece}.{ext}"));
            let third = DumpFile::open(&source).unwrap().frame_bytes(2).unwrap();
            for &cut in cuts {
                let case =
                    format!("piece {cut_piece} of the .{ext} set cut {cut} bytes into frame 2");
                let dir = tempfile::tempdir().unwrap();
                let write = |cut: Option<usize>| {
                    for (k, bytes) in whole.iter().enumerate() {
                        let bytes = match cut {
                            Some(c) if k == cut_piece => &bytes[..third.start as usize + c],
                            _ => &bytes[..],
                        };
                        std::fs::write(dir.path().join(format!("run.{k}.{ext}")), bytes).unwrap();
                    }
                };
                write(Some(cut));
                let set = dir.path().join(format!("run.%.{ext}"));
                let out = dir.path().join("out");
                let r = batch(std::slice::from_ref(&set), &out, &opts(), &NoProgress)
                    .unwrap_or_else(|e| panic!("{case}: {e}"));
                assert_eq!((r.converted, r.incomplete.len()), (2, 1), "{case}");
                let piece = dir.path().join(format!("run.{cut_piece}.{ext}"));
                let note = r.incomplete[0].to_string();
                assert!(
                    note.contains(&piece.display().to_string()),
                    "{case}: {note}"
                );
                let m = read_manifest(&out).unwrap();
                assert_eq!((m.frames.len(), m.expected_frames), (2, Some(2)), "{case}");
                assert!(m.frames.iter().all(|f| f.particles == 500), "{case}");
                check_manifest(&out, &m);
                // The run writes the rest: the rerun converts the third frame alone.
                write(None);
                let r = batch(std::slice::from_ref(&set), &out, &opts(), &NoProgress)
                    .unwrap_or_else(|e| panic!("{case}, complete: {e}"));
                assert_eq!(
                    (r.converted, r.skipped, r.kept_unchanged, r.incomplete.len()),
                    (1, 2, 2, 0),
                    "{case}, complete"
                );
                check_manifest(&out, &read_manifest(&out).unwrap());
            }
        }
    }
}

/// A rerun with `attribute_log10` as before keeps the frames (the atom ids, all above 0,
/// stand for a positive quantity); turning it on or off
/// converts them again (the file holds `log10(NAME)` or `NAME`).
#[test]
fn a_rerun_keeps_or_redoes_frames_by_the_attributes_logarithm() {
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let out = dir.path().join("out");
    let with = |log: bool| {
        let mut o = opts();
        o.read.attribute = Some("id".into());
        o.convert.attribute_log10 = log;
        o
    };
    let r = batch(std::slice::from_ref(&src), &out, &with(true), &NoProgress).unwrap();
    assert_eq!(r.converted, 6);
    let f = MdlodFile::open(out.join("frame-0.mdlod")).unwrap();
    assert_eq!(f.metadata().attribute.as_ref().unwrap().name, "log10(id)");
    let r = batch(std::slice::from_ref(&src), &out, &with(true), &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped), (0, 6));
    let r = batch(std::slice::from_ref(&src), &out, &with(false), &NoProgress).unwrap();
    assert_eq!((r.converted, r.redone.settings), (6, 6));
}

/// A note that only some frames give says which: a lost atom in one frame of three.
#[test]
fn a_note_of_some_frames_names_their_timesteps() {
    let dir = tempfile::tempdir().unwrap();
    let mut text = String::new();
    for step in [0, 100, 200] {
        text.push_str(&format!(
            "ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ATOMS\n50\nITEM: BOX BOUNDS pp pp pp\n\
             0 10\n0 10\n0 10\nITEM: ATOMS id type x y z\n"
        ));
        for i in 0..50 {
            let x = if step == 100 && i == 0 {
                5000.0
            } else {
                (i % 10) as f32
            };
            text.push_str(&format!("{} 1 {x} {} 1\n", i + 1, i / 10));
        }
    }
    let src = dir.path().join("lost.lammpstrj");
    std::fs::write(&src, text).unwrap();
    let r = batch(
        std::slice::from_ref(&src),
        &dir.path().join("out"),
        &opts(),
        &NoProgress,
    )
    .unwrap();
    let note = r
        .notes
        .iter()
        .find(|n| n.contains("box lengths outside"))
        .unwrap();
    assert!(note.ends_with("(timestep 100)"), "{note}");
}

/// Between the manifest's rewrites (at most once a second, here once an hour) the frames
/// finished are listed by [`ManifestHandle::save_now`], which a handler of SIGTERM (a
/// scheduler's time limit) calls before the program exits: the manifest then lists every
/// frame finished, and only complete ones.
#[test]
fn a_manifest_handle_lists_the_frames_finished_between_rewrites() {
    use mdlod_preprocess::batch::ManifestHandle;
    use std::sync::Mutex;
    struct SaveAfter {
        handle: ManifestHandle,
        dir: PathBuf,
        converting: std::sync::atomic::AtomicBool,
        done: std::sync::atomic::AtomicUsize,
        seen: Mutex<Option<(usize, bool, usize)>>,
    }
    impl mdlod_preprocess::Progress for SaveAfter {
        fn stage(&self, name: &str, _total: Option<u64>, _unit: &'static str) {
            self.converting.store(
                name.starts_with("converting"),
                std::sync::atomic::Ordering::SeqCst,
            );
        }
        fn advance(&self, _amount: u64) {
            use std::sync::atomic::Ordering::SeqCst;
            if !self.converting.load(SeqCst) || self.done.fetch_add(1, SeqCst) + 1 != 3 {
                return;
            }
            // Three frames finished: the manifest on disk lists none yet.
            let before = read_manifest(&self.dir).unwrap().frames.len();
            let saved = self.handle.save_now().unwrap();
            let after = read_manifest(&self.dir).unwrap();
            check_manifest(&self.dir, &after);
            *self.seen.lock().unwrap() = Some((before, saved, after.frames.len()));
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let out = dir.path().join("out");
    let handle = ManifestHandle::default();
    let progress = SaveAfter {
        handle: handle.clone(),
        dir: out.clone(),
        converting: false.into(),
        done: 0.into(),
        seen: Mutex::new(None),
    };
    let o = BatchOptions {
        handle: Some(handle.clone()),
        manifest_interval: Some(std::time::Duration::from_secs(3600)),
        max_jobs: Some(1),
        ..opts()
    };
    let r = batch(std::slice::from_ref(&src), &out, &o, &progress).unwrap();
    assert_eq!(r.converted, 6);
    assert_eq!(*progress.seen.lock().unwrap(), Some((0, true, 3)));
    // The batch is over: the handle has nothing to write.
    assert!(!handle.save_now().unwrap());
    assert_eq!(read_manifest(&out).unwrap().frames.len(), 6);
}

/// The 6-frame real dump split into a file set in `dir`, one file per frame
/// (`dump.<timestep>.txt`), by timestep.
fn file_set(dir: &Path) -> Vec<PathBuf> {
    use mdlod_preprocess::readers::DumpFile;
    std::fs::create_dir_all(dir).unwrap();
    let path = lammps_sample_path("cu_melt.custom.dump");
    let whole = std::fs::read(&path).unwrap();
    let frames = DumpFile::open(&path).unwrap();
    (0..frames.frame_count())
        .map(|k| {
            let r = frames.frame_bytes(k).unwrap();
            let t = frames.frame_timestep(k).unwrap();
            let p = dir.join(format!("dump.{t}.txt"));
            std::fs::write(&p, &whole[r.start as usize..r.end as usize]).unwrap();
            p
        })
        .collect()
}

/// Array tasks started before and after a file set grew split different lists of
/// frames (shard 0 of 2 takes 0, 200 of four frames, shard 1 takes 100, 300, 500 of
/// six: 400 belongs to neither): the merge refuses, naming the shards and what each saw,
/// and so does verify; rerun over the whole set, they merge. Manifests of earlier
/// versions, which record no list, are not refused.
#[test]
fn merge_refuses_shards_that_split_different_lists_of_frames() {
    use mdlod_preprocess::batch::verify_dir;
    let dir = tempfile::tempdir().unwrap();
    let all = file_set(&dir.path().join("src"));
    let out = dir.path().join("out");
    batch(&all[..4], &out, &shard(0, 2), &NoProgress).unwrap();
    batch(&all, &out, &shard(1, 2), &NoProgress).unwrap();
    let e = merge(&out).unwrap_err().to_string();
    assert!(
        e.contains("different lists of input frames")
            && e.contains("dataset.shard-0-of-2.json saw 4 frames")
            && e.contains("dataset.shard-1-of-2.json saw 6 frames")
            && e.contains("rerun every shard over the same, complete inputs"),
        "{e}"
    );
    assert!(!out.join("dataset.json").exists());
    let c = verify_dir(&out, &NoProgress).unwrap();
    assert!(
        c.problems
            .iter()
            .any(|p| p.contains("different lists of input frames")),
        "{c:?}"
    );
    // The same count, other timesteps: told apart by the digest.
    let other = dir.path().join("other");
    let mut swapped = all[..3].to_vec();
    swapped.push(all[4].clone());
    batch(&all[..4], &other, &shard(0, 2), &NoProgress).unwrap();
    batch(&swapped, &other, &shard(1, 2), &NoProgress).unwrap();
    let e = merge(&other).unwrap_err().to_string();
    assert!(e.contains("4 frames (of other files or timesteps)"), "{e}");

    batch(&all, &out, &shard(0, 2), &NoProgress).unwrap();
    let m = merge(&out).unwrap();
    assert_eq!(m.frames.len(), 6);
    assert_eq!(m.input_frames.as_ref().map(|l| l.count), Some(6));
    check_manifest(&out, &m);

    // A manifest without the list (an earlier version's) is not compared.
    let path = out.join("dataset.shard-0-of-2.json");
    let mut old: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    old.as_object_mut().unwrap().remove("input_frames").unwrap();
    std::fs::write(&path, serde_json::to_vec(&old).unwrap()).unwrap();
    let m = merge(&out).unwrap();
    assert_eq!((m.frames.len(), m.input_frames), (6, None));
}

/// An old-revision binary dump needs `--columns`: a rerun that forgets them fails on
/// every frame before writing anything, and leaves the manifest as it was (a first run
/// leaves none), so the corrected rerun keeps every frame instead of converting them
/// all again for "other settings".
#[test]
fn a_rerun_failing_before_any_output_leaves_the_manifest_as_it_was() {
    use mdlod_preprocess::readers::DumpFile;
    let dir = tempfile::tempdir().unwrap();
    let new = lammps_sample_path("cu_melt.custom.bin");
    let columns = DumpFile::open(&new).unwrap().frame_info(0).unwrap().columns;
    let src = dir.path().join("old.bin");
    std::fs::write(
        &src,
        mdlod_datasets::to_old_revision(&std::fs::read(&new).unwrap()),
    )
    .unwrap();
    let with_columns = |o: BatchOptions| {
        let mut o = o;
        o.read.columns = Some(columns.clone());
        o
    };
    // A first run without them writes no manifest.
    let fresh = dir.path().join("fresh");
    let e = batch(std::slice::from_ref(&src), &fresh, &opts(), &NoProgress).unwrap_err();
    assert!(e.to_string().contains("give the column names"), "{e}");
    assert!(!fresh.join("dataset.json").exists());

    for (out, o) in [("whole", opts()), ("sharded", shard(1, 2))] {
        let out = dir.path().join(out);
        let r = batch(
            std::slice::from_ref(&src),
            &out,
            &with_columns(o.clone()),
            &NoProgress,
        )
        .unwrap();
        assert!(r.converted > 0);
        let before = std::fs::read(&r.manifest).unwrap();
        let e = batch(std::slice::from_ref(&src), &out, &o, &NoProgress).unwrap_err();
        assert!(e.to_string().contains("give the column names"), "{e}");
        assert_eq!(
            std::fs::read(&r.manifest).unwrap(),
            before,
            "{}",
            r.manifest.display()
        );
        let again = batch(
            std::slice::from_ref(&src),
            &out,
            &with_columns(o),
            &NoProgress,
        )
        .unwrap();
        assert_eq!(
            (again.converted, again.skipped, again.redone.settings),
            (0, r.converted, 0)
        );
    }
}

/// A quoted pattern over the directory that holds the batch directory (`'fs2/*' -o
/// fs2/out`) matches the inputs again on a rerun, not the batch directory; over the
/// batch directory itself, not the frames and manifests the batch wrote there; and not
/// hidden files, as the shell's.
#[test]
fn a_quoted_pattern_skips_directories_and_the_batchs_own_files() {
    use mdlod_preprocess::batch::expand_patterns;
    let dir = tempfile::tempdir().unwrap();
    let fs2 = dir.path().join("fs2");
    let all = file_set(&fs2);
    let names = |v: &[PathBuf]| -> Vec<String> {
        v.iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect()
    };
    let pattern = fs2.join("*");
    let out = fs2.join("out");
    std::fs::write(fs2.join(".hidden.txt"), "not an input").unwrap();
    for run in 0..2 {
        let inputs = expand_patterns(std::slice::from_ref(&pattern), &out).unwrap();
        assert_eq!(names(&inputs), names(&all), "run {run}");
        let r = batch(&inputs, &out, &opts(), &NoProgress).unwrap();
        assert_eq!(r.frames_total, 6);
    }
    // The batch directory is the pattern's: its frames and manifest are not inputs.
    let inputs = expand_patterns(std::slice::from_ref(&pattern), &fs2).unwrap();
    batch(&inputs, &fs2, &opts(), &NoProgress).unwrap();
    assert!(fs2.join("dataset.json").exists() && fs2.join("frame-0.mdlod").exists());
    let again = expand_patterns(std::slice::from_ref(&pattern), &fs2).unwrap();
    assert_eq!(names(&again), names(&all));
    // Elsewhere, files of such names are inputs like any others.
    let e = expand_patterns(&[fs2.join("out").join("*.mdlod")], &fs2).unwrap();
    assert_eq!(e.len(), 6);
    // Nothing but directories: no file matches.
    let e = expand_patterns(&[fs2.join("ou*")], &fs2).unwrap_err();
    assert!(e.to_string().contains("no file matches"), "{e}");
}

/// Only the newest file of a set may be one a run is still writing: one cut short before
/// it (in its atoms, its header or its last line) is an error naming it, where the newest
/// cut so is left out with a note; an empty newest file (just opened) is left out too,
/// an empty older one is an error.
#[test]
fn only_the_newest_file_of_a_set_may_be_cut_short() {
    use mdlod_preprocess::batch::BatchReport;
    let dir = tempfile::tempdir().unwrap();
    let all = file_set(&dir.path().join("src"));
    let whole: Vec<Vec<u8>> = all.iter().map(|p| std::fs::read(p).unwrap()).collect();
    type Cut = fn(&[u8]) -> &[u8];
    let cuts: [(&str, Cut); 4] = [
        ("in its atoms", |b| &b[..b.len() / 2]),
        ("in its header", |b| &b[..30]),
        ("inside its last line", |b| &b[..b.len() - 2]),
        ("to nothing", |b| &b[..0]),
    ];
    for (how, cut) in cuts {
        for (which, k) in [("older", 2), ("newest", 5)] {
            let run = dir.path().join(format!("{how} {which}"));
            let set = run.join("set");
            std::fs::create_dir_all(&set).unwrap();
            let inputs: Vec<PathBuf> = all
                .iter()
                .zip(&whole)
                .enumerate()
                .map(|(i, (p, bytes))| {
                    let q = set.join(p.file_name().unwrap());
                    std::fs::write(&q, if i == k { cut(bytes) } else { &bytes[..] }).unwrap();
                    q
                })
                .collect();
            let r: Result<BatchReport, BatchError> =
                batch(&inputs, &run.join("out"), &opts(), &NoProgress);
            let name = inputs[k].display().to_string();
            match (which, r) {
                ("older", Err(e)) => {
                    let e = e.to_string();
                    assert!(e.contains(&name), "{how} {which}: {e}");
                    let newest = format!("not the newest input ({})", inputs[5].display());
                    assert!(
                        e.contains(&newest) || e.contains("file is empty"),
                        "{how} {which}: {e}"
                    );
                }
                ("newest", Ok(r)) => {
                    assert_eq!((r.converted, r.incomplete.len()), (5, 1), "{how} {which}");
                    let note = r.incomplete[0].to_string();
                    assert!(note.starts_with(&name), "{how}: {note}");
                    let m = read_manifest(&run.join("out")).unwrap();
                    assert_eq!((m.frames.len(), m.expected_frames), (5, Some(5)), "{how}");
                }
                (_, r) => panic!("{how} {which}: {:?}", r.map(|r| r.converted)),
            }
        }
    }
}

/// A failed array task resubmitted alone (`sbatch --array=2`) runs as shard 0 of 1: the
/// merge names the manifests of the two shardings and says how to rerun the missing
/// task and that the stray manifest can then be deleted; done so, the shards merge.
#[test]
fn merge_of_a_task_resubmitted_alone_names_the_stray_manifest_and_the_shard_to_rerun() {
    use mdlod_preprocess::batch::verify_dir;
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let out = dir.path().join("out");
    for i in [0, 1, 3] {
        batch(std::slice::from_ref(&src), &out, &shard(i, 4), &NoProgress).unwrap();
    }
    batch(std::slice::from_ref(&src), &out, &shard(0, 1), &NoProgress).unwrap();
    let e = merge(&out).unwrap_err().to_string();
    assert!(
        e.contains(
            "dataset.shard-0-of-4.json, dataset.shard-1-of-4.json and dataset.shard-3-of-4.json \
             are of 4 shards, but dataset.shard-0-of-1.json is of 1"
        ) && e.contains("rerun the task with --shard 2/4")
            && e.contains("then delete dataset.shard-0-of-1.json and merge"),
        "{e}"
    );
    let c = verify_dir(&out, &NoProgress).unwrap();
    assert!(
        c.problems.iter().any(|p| p.contains("--shard 2/4")),
        "{c:?}"
    );
    let r = batch(std::slice::from_ref(&src), &out, &shard(2, 4), &NoProgress).unwrap();
    assert_eq!(r.converted, 0, "shard 0 of 1 converted its frames already");
    std::fs::remove_file(out.join("dataset.shard-0-of-1.json")).unwrap();
    check_manifest(&out, &merge(&out).unwrap());
}

/// Frames above the chunk size each need one chunk's build (its fixed part dominating
/// small chunks): a batch runs as few at once as fit the memory limit rather than
/// dividing it into shares too small for any, and where one frame does not fit the
/// whole limit, the error names the limit given.
#[test]
fn a_batch_runs_fewer_chunked_frames_at_once_to_fit_the_memory_limit() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("melt.bin");
    std::fs::copy(lammps_sample_path("cu_melt.custom.bin"), &src).unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(4)
        .build()
        .unwrap();
    let run = |limit: u64, out: &str| {
        let mut o = opts();
        o.convert.build.max_root_points = 64;
        o.convert.chunks.chunk_points = 300;
        o.memory_limit = limit;
        let out = dir.path().join(out);
        pool.install(|| batch(std::slice::from_ref(&src), &out, &o, &NoProgress))
    };
    // One chunk of 300 needs 64 MiB and a little: one frame at a time.
    let r = run(100 << 20, "fits").unwrap();
    assert_eq!((r.converted, r.jobs), (3, 1));
    let r = run(140 << 20, "two").unwrap();
    assert_eq!((r.converted, r.jobs), (3, 2));
    let e = run(50 << 20, "small").unwrap_err().to_string();
    assert!(e.contains("the memory limit of 50 MiB is below"), "{e}");
}

/// A manifest is read from wherever a batch directory comes from: a frame file outside
/// the directory, a version this mdlod does not read or a shard field that disagrees
/// with the manifest's name are refused, naming the manifest.
#[test]
fn hostile_manifests_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let out = dir.path().join("out");
    batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    let path = out.join("dataset.json");
    let good: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    let with = |f: &dyn Fn(&mut serde_json::Value)| {
        let mut v = good.clone();
        f(&mut v);
        std::fs::write(&path, serde_json::to_vec(&v).unwrap()).unwrap();
        read_manifest(&out).map(|_| ()).map_err(|e| e.to_string())
    };
    assert_eq!(with(&|_| ()), Ok(()));
    for (file, says) in [
        (
            "/etc/passwd",
            "\"/etc/passwd\" is not a file name inside the directory",
        ),
        (
            "../frame-0.mdlod",
            "\"../frame-0.mdlod\" is not a file name",
        ),
        (
            "sub/frame-0.mdlod",
            "\"sub/frame-0.mdlod\" is not a file name",
        ),
    ] {
        let e = with(&|v| v["frames"][0]["file"] = file.into()).unwrap_err();
        assert!(e.contains("dataset.json") && e.contains(says), "{e}");
    }
    let e = with(&|v| v["mdlod_dataset"] = 2.into()).unwrap_err();
    assert!(
        e.contains("mdlod_dataset 2 (this mdlod reads version 1)"),
        "{e}"
    );
    let e = with(&|v| v["shard"] = serde_json::json!([5, 2])).unwrap_err();
    assert!(e.contains("shard [5, 2]"), "{e}");
    // A shard manifest whose field disagrees with its name is refused by the merge.
    let sharded = dir.path().join("sharded");
    for i in 0..2 {
        batch(
            std::slice::from_ref(&src),
            &sharded,
            &shard(i, 2),
            &NoProgress,
        )
        .unwrap();
    }
    let one = sharded.join("dataset.shard-1-of-2.json");
    let mut v: serde_json::Value = serde_json::from_slice(&std::fs::read(&one).unwrap()).unwrap();
    v["shard"] = serde_json::json!([0, 2]);
    std::fs::write(&one, serde_json::to_vec(&v).unwrap()).unwrap();
    let check = mdlod_preprocess::batch::verify_dir(&sharded, &NoProgress).unwrap();
    assert!(
        check.problems.iter().any(|p| p.contains(
            "dataset.shard-1-of-2.json: its shard field is [0, 2] but its name says shard 1 of 2"
        )),
        "{:?}",
        check.problems
    );
    let e = merge(&sharded).unwrap_err().to_string();
    assert!(
        e.contains("dataset.shard-1-of-2.json") && e.contains("its shard field is [0, 2]"),
        "{e}"
    );
}

/// A rerun that converts a frame again with another particle count says so: the last
/// piece of a `%` set gone (no gap in the numbering shows it) rebuilt every frame with
/// half the atoms, noted only as "source changed".
#[test]
fn a_rerun_whose_frames_change_size_says_so() {
    let dir = tempfile::tempdir().unwrap();
    for i in 0..2 {
        std::fs::copy(
            lammps_sample_path(&format!("cu_melt_mpi.{i}.bin")),
            dir.path().join(format!("p.{i}.bin")),
        )
        .unwrap();
    }
    let pattern = dir.path().join("p.%.bin");
    let out = dir.path().join("out");
    let r = batch(std::slice::from_ref(&pattern), &out, &opts(), &NoProgress).unwrap();
    assert!(
        !r.notes.iter().any(|n| n.contains("particle counts")),
        "{:?}",
        r.notes
    );
    std::fs::remove_file(dir.path().join("p.1.bin")).unwrap();
    let r = batch(std::slice::from_ref(&pattern), &out, &opts(), &NoProgress).unwrap();
    assert!(
        r.notes
            .iter()
            .any(|n| n.contains("particle counts changed since the last run")
                && n.contains("holds 250 particles, 500 before")),
        "{:?}",
        r.notes
    );
    // A text dump whose frames' bytes changed (checked by their bytes) says so too.
    let src = input(dir.path());
    let text_out = dir.path().join("text");
    batch(std::slice::from_ref(&src), &text_out, &opts(), &NoProgress).unwrap();
    // The last frame loses its last atom.
    let text = std::fs::read_to_string(&src).unwrap();
    let at = text.rfind("NUMBER OF ATOMS\n500\n").unwrap();
    let mut shorter = format!("{}NUMBER OF ATOMS\n499\n{}", &text[..at], &text[at + 20..]);
    shorter.truncate(shorter.trim_end_matches('\n').rfind('\n').unwrap() + 1);
    std::fs::write(&src, shorter).unwrap();
    let r = batch(std::slice::from_ref(&src), &text_out, &opts(), &NoProgress).unwrap();
    assert!(
        r.notes.iter().any(|n| n.contains("particle counts changed")
            && n.contains("holds 499 particles, 500 before")),
        "{:?}",
        r.notes
    );
}

/// An older gzip file of a set whose compressed stream ends early (cut right after a
/// frame, as `dump custom/gz` flushes them) is an error naming it: its frames past the
/// cut would vanish, where a newest file so cut is read up to the cut.
#[test]
fn an_older_gzip_file_cut_short_is_an_error() {
    use std::io::Write;
    let dir = tempfile::tempdir().unwrap();
    let all = file_set(&dir.path().join("src"));
    let texts: Vec<Vec<u8>> = all.iter().map(|p| std::fs::read(p).unwrap()).collect();
    // Two frames in one gzip stream, flushed after the first and cut there.
    let cut_after_first = |a: &[u8], b: &[u8]| {
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
        enc.write_all(a).unwrap();
        enc.flush().unwrap();
        let cut = enc.get_ref().clone();
        enc.write_all(b).unwrap();
        (cut, enc.finish().unwrap())
    };
    let gz = |bytes: &[u8]| {
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
        enc.write_all(bytes).unwrap();
        enc.finish().unwrap()
    };
    for (which, at) in [("older", 0), ("newest", 4)] {
        let set = dir.path().join(which);
        std::fs::create_dir_all(&set).unwrap();
        let mut inputs = Vec::new();
        let mut k = 0;
        while k < texts.len() {
            let name = set.join(format!("dump.{k}.gz"));
            if k == at {
                let (cut, _) = cut_after_first(&texts[k], &texts[k + 1]);
                std::fs::write(&name, cut).unwrap();
                k += 2;
            } else {
                std::fs::write(&name, gz(&texts[k])).unwrap();
                k += 1;
            }
            inputs.push(name);
        }
        let r = batch(&inputs, &set.join("out"), &opts(), &NoProgress);
        match (which, r) {
            ("older", Err(e)) => {
                let e = e.to_string();
                assert!(
                    e.contains("dump.0.gz is cut short, but it is not the newest input")
                        && e.contains("its compressed stream ends early"),
                    "{e}"
                );
            }
            ("newest", Ok(r)) => assert_eq!(r.converted, 5),
            (_, r) => panic!("{which}: {:?}", r.map(|r| r.converted)),
        }
    }
    // A newest gzip file holding its header and no text yet (just opened) is left out
    // as an empty one is.
    let set = dir.path().join("opened");
    std::fs::create_dir_all(&set).unwrap();
    let mut inputs = Vec::new();
    for (k, text) in texts.iter().enumerate() {
        let name = set.join(format!("dump.{k}.gz"));
        let bytes = gz(text);
        let keep = if k + 1 == texts.len() {
            10
        } else {
            bytes.len()
        };
        std::fs::write(&name, &bytes[..keep]).unwrap();
        inputs.push(name);
    }
    let r = batch(&inputs, &set.join("out"), &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.incomplete.len()), (texts.len() - 1, 1));
    assert!(r.incomplete[0].empty_file, "{}", r.incomplete[0]);
}

/// Shards run with different `--species-name` renames make frames whose species differ
/// in name, radius and colour (a movie flips between them): the merge refuses them.
#[test]
fn merge_refuses_shards_with_different_renames() {
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let out = dir.path().join("out");
    let mut renamed = shard(0, 2);
    renamed.convert.species_names = vec![("1".into(), "Cu".into())];
    renamed.convert.radii = vec![("Cu".into(), 1.28)];
    batch(std::slice::from_ref(&src), &out, &renamed, &NoProgress).unwrap();
    batch(std::slice::from_ref(&src), &out, &shard(1, 2), &NoProgress).unwrap();
    let e = merge(&out).unwrap_err().to_string();
    assert!(
        e.contains("built with different settings")
            && e.contains("--species-name 1=Cu")
            && e.contains("--species-name none"),
        "{e}"
    );
}

/// A frame file no manifest records (a run killed within a second of finishing it,
/// before it listed it) is converted again: the file alone cannot say which renames or
/// wrapping it was read with, and a rerun without the killed run's renames kept frames
/// holding them, which `verify` passed.
#[test]
fn frames_no_manifest_records_are_converted_again() {
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let out = dir.path().join("out");
    batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    let listed = std::fs::read(out.join("dataset.json")).unwrap();
    let mut renamed = opts();
    renamed.convert.species_names = vec![("1".into(), "Cu".into())];
    let r = batch(std::slice::from_ref(&src), &out, &renamed, &NoProgress).unwrap();
    assert_eq!((r.converted, r.redone.settings), (6, 6));
    // As if killed before it listed a frame: the manifest is the first run's, whose
    // records are of files since replaced.
    std::fs::write(out.join("dataset.json"), &listed).unwrap();
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!(
        (
            r.converted,
            r.skipped,
            r.redone.unrecorded,
            r.redone.settings
        ),
        (6, 0, 6, 0)
    );
    let m = read_manifest(&out).unwrap();
    check_manifest(&out, &m);
    for f in &m.frames {
        let file = MdlodFile::open(out.join(&f.file)).unwrap();
        let names: Vec<&str> = file
            .metadata()
            .species
            .iter()
            .map(|s| s.name.as_str())
            .collect();
        assert_eq!(names, ["1"], "{}", f.file);
    }
    // Listed now: the next run keeps them all.
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped), (0, 6));
}

/// Frame files of inputs a run was not given keep their records beside its manifest
/// (`.dataset.records.json`), which lists only its own: a run over the whole set again
/// keeps them, where it converted them again for want of a record.
#[test]
fn frames_of_inputs_left_out_of_a_run_keep_their_records() {
    let dir = tempfile::tempdir().unwrap();
    let all = file_set(&dir.path().join("src"));
    let out = dir.path().join("out");
    batch(&all, &out, &opts(), &NoProgress).unwrap();
    let r = batch(&all[..3], &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped, r.strays.len()), (0, 3, 3));
    assert_eq!(read_manifest(&out).unwrap().frames.len(), 3);
    assert!(out.join(".dataset.records.json").exists());
    let r = batch(&all, &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped, r.redone.unrecorded), (0, 6, 0));
    // Nothing left unlisted: no records beside the manifest.
    assert!(!out.join(".dataset.records.json").exists());
    // Shards keep none of each other's records: each lists its own frames.
    let sharded = dir.path().join("sharded");
    for i in 0..2 {
        batch(&all, &sharded, &shard(i, 2), &NoProgress).unwrap();
    }
    let r = batch(&all, &sharded, &shard(0, 2), &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped), (0, 3));
    let side: Vec<String> = std::fs::read_dir(&sharded)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".records.json"))
        .collect();
    assert!(side.is_empty(), "{side:?}");
}

/// A rename of a species no frame can hold (a type number where the input names
/// elements, an element where it names type numbers) is refused before any frame is
/// converted, as a radius for one is; it did nothing, or failed after every frame.
#[test]
fn impossible_renames_are_refused_before_converting() {
    let dir = tempfile::tempdir().unwrap();
    for (sample, old, says) in [
        (
            "cuag_alloy.unwrapped.dump",
            "1",
            "names its species by its `element` column",
        ),
        (
            "cu_melt.custom.dump",
            "Zn",
            "names its species by LAMMPS type number",
        ),
    ] {
        let out = dir.path().join(sample);
        let mut o = opts();
        o.convert.species_names = vec![(old.into(), "X".into())];
        let e = batch(&[lammps_sample_path(sample)], &out, &o, &NoProgress)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(&format!(
                "--species-name {old}=X: no species named \"{old}\" can occur there"
            )) && e.contains(says),
            "{e}"
        );
        assert!(!out.join("dataset.json").exists());
    }
}

/// A single gzip dump still being written, cut inside its last frame's atoms: the frames
/// before the cut convert, the cut one is left out for a rerun, and the summary's notes
/// say the compressed stream ends early (the frame's description, read while listing,
/// failed the whole batch).
#[test]
fn a_gzip_dump_cut_inside_its_last_frame_converts_the_frames_before() {
    use std::io::Write;
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read(lammps_sample_path("cu_melt.custom.dump")).unwrap();
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    // The last frame's first 3000 bytes (a tenth of its atoms: too few lines for the
    // count its header announces), flushed as a run does.
    let last = String::from_utf8_lossy(&text)
        .rfind("ITEM: TIME\n")
        .unwrap();
    enc.write_all(&text[..last + 3000]).unwrap();
    enc.flush().unwrap();
    let cut = enc.get_ref().clone();
    let src = dir.path().join("live.dump.gz");
    std::fs::write(&src, cut).unwrap();
    let r = batch(
        std::slice::from_ref(&src),
        &dir.path().join("out"),
        &opts(),
        &NoProgress,
    )
    .unwrap();
    assert_eq!((r.converted, r.incomplete.len()), (5, 1));
    assert!(
        r.notes
            .iter()
            .any(|n| n.contains("compressed stream cut short: ")
                && n.contains("live.dump.gz ends early")
                // About the file: no timesteps of frames that converted fine.
                && !n.contains("(timestep")),
        "{:?}",
        r.notes
    );
    // Converting the cut frame, or one past it, by its index: the error says the
    // compressed stream ends early (it said only "truncated frame" or "does not exist").
    let o = opts();
    for (k, says) in [(5, "truncated frame"), (6, "frame 6 does not exist")] {
        let e = mdlod_preprocess::convert::convert_file(
            &src,
            &dir.path().join("one.mdlod"),
            mdlod_preprocess::convert::FrameSelect::Index(k),
            &o.read,
            &o.convert,
            &NoProgress,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains(says) && e.contains("live.dump.gz's compressed stream ends early"),
            "{e}"
        );
    }
}

/// The species column is recorded per frame: a rerun with another converts every frame
/// again, one with the same skips them, and shards converted with different ones do not
/// merge.
#[test]
fn a_rerun_with_another_species_column_converts_again_and_shards_must_agree() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("alloy.dump");
    std::fs::copy(lammps_sample_path("cuag_alloy.unwrapped.dump"), &src).unwrap();
    let out = dir.path().join("out");
    let with = |column: Option<&str>, base: BatchOptions| {
        let mut o = base;
        o.read.species_column = column.map(String::from);
        o
    };
    let run = |column: Option<&str>| {
        let r = batch(
            std::slice::from_ref(&src),
            &out,
            &with(column, opts()),
            &NoProgress,
        )
        .unwrap();
        (r.converted, r.skipped)
    };
    let species = || {
        let m = read_manifest(&out).unwrap();
        let f = MdlodFile::open(out.join(&m.frames[0].file)).unwrap();
        let names: Vec<String> = f
            .metadata()
            .species
            .iter()
            .map(|s| s.name.clone())
            .collect();
        // The file records the column as its manifest entry does.
        assert_eq!(f.metadata().species_column, m.frames[0].species_column);
        (names, m.frames[0].species_column.clone())
    };
    assert_eq!(run(None), (5, 0));
    assert_eq!(species(), (vec!["Cu".to_string(), "Ag".to_string()], None));
    assert_eq!(run(Some("type")), (5, 0));
    assert_eq!(
        species(),
        (
            vec!["1".to_string(), "2".to_string()],
            Some("type".to_string())
        )
    );
    assert_eq!(run(Some("type")), (0, 5));
    assert_eq!(run(None), (5, 0));
    assert_eq!(species().1, None);
    // Names and radii for the values, one of them in no frame (a script naming every
    // structure type): converted, the absent one passed over.
    let mut named = with(Some("type"), opts());
    named.convert.species_names = vec![("1".into(), "FCC".into()), ("3".into(), "BCC".into())];
    named.convert.radii = vec![("FCC".into(), 1.3), ("BCC".into(), 1.2), ("2".into(), 1.5)];
    let r = batch(std::slice::from_ref(&src), &out, &named, &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped), (5, 0));
    assert!(
        r.notes
            .iter()
            .any(|n| n == "--species-name 3=BCC: no frame has the value 3 in --species-column type"),
        "{:?}",
        r.notes
    );
    let m = read_manifest(&out).unwrap();
    let f = MdlodFile::open(out.join(&m.frames[0].file)).unwrap();
    let radii: Vec<(String, f32)> = f
        .metadata()
        .species
        .iter()
        .map(|s| (s.name.clone(), s.radius))
        .collect();
    assert_eq!(radii, [("FCC".to_string(), 1.3), ("2".to_string(), 1.5)]);
    // A continuous column by mistake: a species per value, and a note.
    let r = batch(
        std::slice::from_ref(&src),
        &dir.path().join("pe"),
        &with(Some("c_pe"), opts()),
        &NoProgress,
    )
    .unwrap();
    assert!(
        r.notes
            .iter()
            .any(|n| n.starts_with("--species-column c_pe gave ")
                && n.contains("a continuous quantity goes in --attribute")),
        "{:?}",
        r.notes
    );
    // A column no frame has is an error before any frame is converted.
    let e = batch(
        std::slice::from_ref(&src),
        &dir.path().join("none"),
        &with(Some("c_nope"), opts()),
        &NoProgress,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("no column `c_nope` for --species-column"), "{e}");
    // Shards of other species columns.
    let merged = dir.path().join("shards");
    batch(
        std::slice::from_ref(&src),
        &merged,
        &shard(0, 2),
        &NoProgress,
    )
    .unwrap();
    batch(
        std::slice::from_ref(&src),
        &merged,
        &with(Some("type"), shard(1, 2)),
        &NoProgress,
    )
    .unwrap();
    let e = merge(&merged).unwrap_err().to_string();
    assert!(
        e.contains("different settings")
            && e.contains("species column none (the input's own species)")
            && e.contains("species column type;"),
        "{e}"
    );
}

/// `keep_going`: a frame holding a NaN is reported with its place and left out of the
/// manifest, which expects only the others, so shards merge; a rerun converts nothing
/// again and reports it again. Without it, that frame is the batch's error.
#[test]
fn keep_going_converts_the_other_frames_and_reports_the_bad_one() {
    let dir = tempfile::tempdir().unwrap();
    let good = std::fs::read_to_string(lammps_sample_path("cu_melt.custom.dump")).unwrap();
    // Frame 2's first atom gets a NaN coordinate.
    let at = good.match_indices("ITEM: ATOMS").nth(2).unwrap().0;
    let line = at + good[at..].find('\n').unwrap() + 1;
    let end = line + good[line..].find('\n').unwrap();
    let mut fields: Vec<&str> = good[line..end].split(' ').collect();
    fields[3] = "nan";
    let bad = format!("{}{}{}", &good[..line], fields.join(" "), &good[end..]);
    let src = dir.path().join("bad.dump");
    std::fs::write(&src, bad).unwrap();
    let out = dir.path().join("out");
    assert!(batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).is_err());
    let keep = BatchOptions {
        keep_going: true,
        ..opts()
    };
    for rerun in [false, true] {
        let r = batch(std::slice::from_ref(&src), &out, &keep, &NoProgress).unwrap();
        assert_eq!(r.failed.len(), 1);
        let f = &r.failed[0];
        assert_eq!((f.frame, f.timestep), (2, Some(200)));
        assert!(
            f.to_string()
                .contains("bad.dump: frame 2 (timestep 200) not converted")
                && f.reason.contains("`nan` is not a finite number"),
            "{f}"
        );
        let m = read_manifest(&out).unwrap();
        assert_eq!(m.frames.len(), 5);
        assert_eq!(m.expected_frames, Some(5));
        // Listed as failed, which verify names as missing.
        assert_eq!(m.failed.len(), 1);
        assert_eq!((m.failed[0].timestep, m.failed[0].frame), (Some(200), 2));
        let v = mdlod_preprocess::batch::verify_dir(&out, &NoProgress).unwrap();
        assert_eq!(v.frames_ok, 5);
        assert!(
            v.problems.len() == 1
                && v.problems[0].contains("timestep 200 (frame 2 of ")
                && v.problems[0].contains("could not be converted"),
            "{:?}",
            v.problems
        );
        assert!(m.frames.iter().all(|f| f.timestep != 200));
        check_manifest(&out, &m);
        if rerun {
            assert_eq!((r.converted, r.skipped), (0, 5));
        }
    }
    // Shards that each pass over their bad frames merge.
    let sharded = dir.path().join("sharded");
    for i in 0..2 {
        let o = BatchOptions {
            keep_going: true,
            ..shard(i, 2)
        };
        batch(std::slice::from_ref(&src), &sharded, &o, &NoProgress).unwrap();
    }
    let merged = merge(&sharded).unwrap();
    assert_eq!(merged.frames.len(), 5);
    assert_eq!(merged.failed.len(), 1);
    // The input mended: a rerun converts the frame, and nothing is failed any more.
    std::fs::write(&src, &good).unwrap();
    let r = batch(std::slice::from_ref(&src), &out, &keep, &NoProgress).unwrap();
    assert!(r.failed.is_empty() && r.converted >= 1, "{r:?}");
    let m = read_manifest(&out).unwrap();
    assert_eq!((m.frames.len(), m.failed.len()), (6, 0));
}

/// A further attribute's column that a later frame lacks is refused before any frame is
/// converted, as the first attribute's is; so are more attributes than a file keeps.
#[test]
fn a_further_attribute_missing_from_a_later_frame_is_refused_up_front() {
    let dir = tempfile::tempdir().unwrap();
    let good = std::fs::read_to_string(lammps_sample_path("cu_melt.custom.dump")).unwrap();
    // Frame 2 lacks c_pe (its column renamed).
    let at = good.match_indices("ITEM: ATOMS").nth(2).unwrap().0;
    let bad = format!(
        "{}{}",
        &good[..at],
        good[at..].replacen(
            "ITEM: ATOMS id type x y z c_pe",
            "ITEM: ATOMS id type x y z c_xx",
            1
        )
    );
    assert_ne!(bad, good);
    let src = dir.path().join("miss.dump");
    std::fs::write(&src, bad).unwrap();
    let out = dir.path().join("out");
    let o = BatchOptions {
        read: mdlod_preprocess::readers::ReadOptions {
            attribute: Some("x".into()),
            extra_attributes: vec!["c_pe".into()],
            ..Default::default()
        },
        ..opts()
    };
    let e = batch(std::slice::from_ref(&src), &out, &o, &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(e.contains("c_pe"), "{e}");
    let converted = std::fs::read_dir(&out)
        .map(|d| {
            d.filter(|e| {
                e.as_ref()
                    .is_ok_and(|e| e.path().extension().is_some_and(|x| x == "mdlod"))
            })
            .count()
        })
        .unwrap_or(0);
    assert_eq!(converted, 0, "{e}");
    let many = BatchOptions {
        read: mdlod_preprocess::readers::ReadOptions {
            attribute: Some("x".into()),
            extra_attributes: (0..65).map(|k| format!("c_{k}")).collect(),
            ..Default::default()
        },
        ..opts()
    };
    let e = batch(
        std::slice::from_ref(&src),
        &dir.path().join("many"),
        &many,
        &NoProgress,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("66 attributes (--attribute): a file keeps at most 65"),
        "{e}"
    );
}

/// `keep_going` over inputs a pattern matched beside the dumps (a run's log): the input
/// that holds no dump fails alone, named, and the dumps convert; without it, the batch
/// stops on it. A path that does not exist stops the batch either way.
#[test]
fn keep_going_passes_over_an_input_that_holds_no_dump() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log.lammps");
    std::fs::write(
        &log,
        "LAMMPS (29 Aug 2024)\nunits metal\nLoop time of 1.2 on 2 procs for 500 steps\n",
    )
    .unwrap();
    let inputs = [log.clone(), input(dir.path())];
    let out = dir.path().join("out");
    let e = batch(&inputs, &out, &opts(), &NoProgress).unwrap_err();
    assert!(e.to_string().contains("log.lammps"), "{e}");
    let keep = BatchOptions {
        keep_going: true,
        ..opts()
    };
    let r = batch(&inputs, &out, &keep, &NoProgress).unwrap();
    assert_eq!(r.failed.len(), 1, "{:?}", r.failed);
    assert_eq!(r.failed[0].input, log);
    assert!(
        r.failed[0].to_string().contains("log.lammps"),
        "{}",
        r.failed[0]
    );
    assert_eq!(r.converted, 6);
    let m = read_manifest(&out).unwrap();
    assert_eq!(m.frames.len(), 6);
    check_manifest(&out, &m);
    let missing = dir.path().join("no-such.dump");
    assert!(batch(&[missing, inputs[1].clone()], &out, &keep, &NoProgress).is_err());
    // Sharded, the input no shard can list is shard 0's alone to report.
    let sharded = dir.path().join("sharded");
    for (i, fails) in [(0, 1), (1, 0)] {
        let keep = BatchOptions {
            keep_going: true,
            ..shard(i, 2)
        };
        let r = batch(&inputs, &sharded, &keep, &NoProgress).unwrap();
        assert_eq!(r.failed.len(), fails, "shard {i}: {:?}", r.failed);
    }
}

/// A batch running into a directory is told by its lock (for a render that meets the
/// directory half rewritten), and none once it ends.
#[test]
fn a_running_batch_is_told_by_its_lock() {
    use mdlod_preprocess::batch::{batch_running, lock_file_name};
    let dir = tempfile::tempdir().unwrap();
    assert_eq!(batch_running(dir.path()), None);
    let path = dir.path().join(lock_file_name(None));
    std::fs::write(&path, "pid 4242 on node17").unwrap();
    assert_eq!(batch_running(dir.path()), None);
    let f = std::fs::File::open(&path).unwrap();
    f.lock().unwrap();
    assert_eq!(
        batch_running(dir.path()).as_deref(),
        Some("pid 4242 on node17")
    );
    drop(f);
    assert_eq!(batch_running(dir.path()), None);
}

/// A rerun with nothing to do writes nothing: the manifest is the same file (inode and
/// all), so a read-only directory of finished frames checks as current.
#[test]
fn a_rerun_with_nothing_to_do_leaves_the_manifest_untouched() {
    use std::os::unix::fs::MetadataExt;
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let out = dir.path().join("out");
    batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    let before = std::fs::metadata(out.join("dataset.json")).unwrap();
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!(r.converted, 0);
    let after = std::fs::metadata(out.join("dataset.json")).unwrap();
    assert_eq!(
        (before.ino(), before.mtime(), before.mtime_nsec()),
        (after.ino(), after.mtime(), after.mtime_nsec())
    );
}

/// A run's log sorted after a set's files (`dump.*` and `log.lammps` matched by one
/// pattern) does not take the newest dump's place: an empty newest dump is still left out
/// as one a run has just opened, not failed, and the log fails alone.
#[test]
fn a_log_sorted_after_the_dumps_leaves_the_empty_newest_dump_for_a_rerun() {
    let dir = tempfile::tempdir().unwrap();
    let all = file_set(&dir.path().join("src"));
    let newest = all.last().unwrap().clone();
    std::fs::write(&newest, b"").unwrap();
    let log = dir.path().join("src").join("zz.log.lammps");
    std::fs::write(&log, "LAMMPS (29 Aug 2024)\nunits metal\n").unwrap();
    let mut inputs = all.clone();
    inputs.push(log.clone());
    let out = dir.path().join("out");
    let keep = BatchOptions {
        keep_going: true,
        ..opts()
    };
    let r = batch(&inputs, &out, &keep, &NoProgress).unwrap();
    assert_eq!(r.converted, all.len() - 1);
    assert_eq!(r.failed.len(), 1, "{:?}", r.failed);
    assert_eq!(r.failed[0].input, log);
    assert_eq!(r.incomplete.len(), 1, "{:?}", r.incomplete);
    assert!(
        r.incomplete[0]
            .to_string()
            .contains("the newest input, is empty"),
        "{}",
        r.incomplete[0]
    );
    assert!(!mdlod_preprocess::readers::plainly_no_dump(&all[0]));
    assert!(!mdlod_preprocess::readers::plainly_no_dump(&newest));
    assert!(mdlod_preprocess::readers::plainly_no_dump(&log));
}

/// `keep_going` with a column asked for (`--attribute`): a frame whose header cannot be
/// read (a box with its bounds reversed) is one failed frame too, not the end of the
/// batch before anything is converted.
#[test]
fn keep_going_passes_over_a_bad_header_when_a_column_is_asked_for() {
    let dir = tempfile::tempdir().unwrap();
    let good = std::fs::read_to_string(lammps_sample_path("cu_melt.custom.dump")).unwrap();
    // Frame 3's x bounds reversed.
    let at = good.match_indices("ITEM: BOX BOUNDS").nth(3).unwrap().0;
    let line = at + good[at..].find('\n').unwrap() + 1;
    let end = line + good[line..].find('\n').unwrap();
    let (lo, hi) = good[line..end].split_once(' ').unwrap();
    let bad = format!("{}{hi} {lo}{}", &good[..line], &good[end..]);
    let src = dir.path().join("box.dump");
    std::fs::write(&src, bad).unwrap();
    let mut o = BatchOptions {
        keep_going: true,
        ..opts()
    };
    o.read.attribute = Some("c_pe".into());
    let out = dir.path().join("out");
    let r = batch(std::slice::from_ref(&src), &out, &o, &NoProgress).unwrap();
    assert_eq!((r.converted, r.failed.len()), (5, 1));
    assert!(
        r.failed[0].reason.contains("BOX BOUNDS") && r.failed[0].frame == 3,
        "{:?}",
        r.failed
    );
    o.keep_going = false;
    assert!(batch(
        std::slice::from_ref(&src),
        &dir.path().join("stop"),
        &o,
        &NoProgress
    )
    .is_err());
    // Compressed, the same frame is a failed one too, not an empty one skipped.
    let gz = dir.path().join("box.dump.gz");
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    std::io::Write::write_all(&mut enc, &std::fs::read(&src).unwrap()).unwrap();
    std::fs::write(&gz, enc.finish().unwrap()).unwrap();
    o.keep_going = true;
    let r = batch(
        std::slice::from_ref(&gz),
        &dir.path().join("gz"),
        &o,
        &NoProgress,
    )
    .unwrap();
    assert_eq!(
        (r.converted, r.failed.len(), r.empty.len()),
        (5, 1, 0),
        "{r:?}"
    );
    assert_eq!(r.failed[0].frame, 3);
}

/// A frame whose TIMESTEP cannot be read is failed before the frames are numbered: no
/// number made up for it (its position) takes a real frame's place, so no good frame is
/// taken for its duplicate and left out.
#[test]
fn a_frame_whose_timestep_cannot_be_read_takes_no_other_frames_place() {
    let dir = tempfile::tempdir().unwrap();
    let good = std::fs::read_to_string(lammps_sample_path("cu_melt.custom.dump")).unwrap();
    let bad = good.replacen("ITEM: TIMESTEP\n200\n", "ITEM: TIMESTEP\n2x0\n", 1);
    assert_ne!(bad, good);
    let src = dir.path().join("ts.dump");
    std::fs::write(&src, bad).unwrap();
    let out = dir.path().join("out");
    let e = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(e.contains("malformed `ITEM: TIMESTEP` value `2x0`"), "{e}");
    let keep = BatchOptions {
        keep_going: true,
        duplicates: mdlod_preprocess::batch::Duplicates::Last,
        ..opts()
    };
    let r = batch(std::slice::from_ref(&src), &out, &keep, &NoProgress).unwrap();
    assert_eq!((r.converted, r.failed.len()), (5, 1));
    assert!(r.duplicates.is_empty(), "{:?}", r.duplicates);
    let m = read_manifest(&out).unwrap();
    let steps: Vec<u64> = m.frames.iter().map(|f| f.timestep).collect();
    assert_eq!(steps, [0, 100, 300, 400, 500]);
    assert_eq!(m.expected_frames, Some(5));
    assert_eq!((m.failed[0].timestep, m.failed[0].frame), (None, 2));
    check_manifest(&out, &m);
}

/// A whole run after a sharded one removes the shard manifests its `dataset.json`
/// supersedes: a later `--merge` cannot put their older frames back over it.
#[test]
fn a_whole_run_removes_the_shard_manifests_it_supersedes() {
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let out = dir.path().join("out");
    for i in 0..2 {
        batch(std::slice::from_ref(&src), &out, &shard(i, 2), &NoProgress).unwrap();
    }
    assert_eq!(merge(&out).unwrap().frames.len(), 6);
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!(
        r.removed_shard_manifests,
        ["dataset.shard-0-of-2.json", "dataset.shard-1-of-2.json"]
    );
    assert!(!out.join("dataset.shard-0-of-2.json").exists());
    assert_eq!(read_manifest(&out).unwrap().frames.len(), 6);
    let e = merge(&out).unwrap_err().to_string();
    assert!(e.contains("no shard manifests"), "{e}");
    assert_eq!(read_manifest(&out).unwrap().frames.len(), 6);
    check_manifest(&out, &read_manifest(&out).unwrap());
}

/// Shards that chose differently among frames of one timestep do not merge (merged, a
/// restart's frames would mix with the abandoned run's); the same choice merges.
#[test]
fn shards_of_other_duplicate_choices_do_not_merge() {
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let out = dir.path().join("out");
    let last = |i| BatchOptions {
        duplicates: mdlod_preprocess::batch::Duplicates::Last,
        ..shard(i, 2)
    };
    batch(std::slice::from_ref(&src), &out, &last(0), &NoProgress).unwrap();
    batch(std::slice::from_ref(&src), &out, &shard(1, 2), &NoProgress).unwrap();
    // Verify says so before a merge is tried.
    let v = mdlod_preprocess::batch::verify_dir(&out, &NoProgress).unwrap();
    assert!(
        v.problems
            .iter()
            .any(|p| p.contains("the shards would not merge") && p.contains("last")),
        "{:?}",
        v.problems
    );
    let e = merge(&out).unwrap_err().to_string();
    assert!(
        e.contains("the shards chose differently among frames of one timestep")
            && e.contains("--duplicate-timesteps last")
            && e.contains("error (the default)"),
        "{e}"
    );
    batch(std::slice::from_ref(&src), &out, &last(1), &NoProgress).unwrap();
    let m = merge(&out).unwrap();
    assert_eq!((m.frames.len(), m.duplicates.as_deref()), (6, Some("last")));
}

/// `wrap` is recorded per frame: a rerun with it keeps the frames, one without converts
/// them again.
#[test]
fn a_rerun_with_another_wrapping_converts_again() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("alloy.dump");
    std::fs::copy(lammps_sample_path("cuag_alloy.unwrapped.dump"), &src).unwrap();
    let out = dir.path().join("out");
    let run = |wrap: bool| {
        let mut o = opts();
        o.read.wrap = wrap;
        let r = batch(std::slice::from_ref(&src), &out, &o, &NoProgress).unwrap();
        (r.converted, r.skipped)
    };
    assert_eq!(run(true), (5, 0));
    let m = read_manifest(&out).unwrap();
    assert!(m.frames.iter().all(|f| f.wrap));
    assert_eq!(run(true), (0, 5));
    assert_eq!(run(false), (5, 0));
    assert!(read_manifest(&out).unwrap().frames.iter().all(|f| !f.wrap));
}

/// A `%` piece set a run is still writing (each piece appended to): a rerun keeps the
/// frames whose bytes in every piece are unchanged, as for one file, and converts the
/// new ones; a frame changed in one piece converts again. Binary pieces rewritten with
/// the same bytes keep every frame.
#[test]
fn piece_sets_appended_to_keep_their_unchanged_frames() {
    let dir = tempfile::tempdir().unwrap();
    // Each text piece cut after its second frame, as a run writing it leaves it.
    let whole: Vec<Vec<u8>> = (0..2)
        .map(|k| std::fs::read(lammps_sample_path(&format!("cu_melt_mpi.{k}.dump"))).unwrap())
        .collect();
    let frame_starts = |text: &[u8]| -> Vec<usize> {
        let item = b"ITEM: TIMESTEP";
        (0..text.len())
            .filter(|&i| text[i..].starts_with(item))
            .collect()
    };
    let piece = |k: usize| dir.path().join(format!("melt.{k}.dump"));
    for (k, text) in whole.iter().enumerate() {
        let starts = frame_starts(text);
        assert_eq!(starts.len(), 3);
        std::fs::write(piece(k), &text[..starts[2]]).unwrap();
    }
    let set = dir.path().join("melt.%.dump");
    let out = dir.path().join("out");
    let r = batch(std::slice::from_ref(&set), &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped), (2, 0));
    let before = read_manifest(&out).unwrap();
    // The run has written its third frame into the first piece only: left out, said.
    std::fs::write(piece(0), &whole[0]).unwrap();
    let r = batch(std::slice::from_ref(&set), &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped), (0, 2));
    assert!(
        r.notes
            .iter()
            .any(|n| n.contains("1 frame past the last that every piece holds")),
        "{:?}",
        r.notes
    );
    // The run writes its third frame into both pieces.
    for (k, text) in whole.iter().enumerate() {
        std::fs::write(piece(k), text).unwrap();
    }
    let r = batch(std::slice::from_ref(&set), &out, &opts(), &NoProgress).unwrap();
    assert_eq!(
        (r.converted, r.skipped, r.kept_unchanged, r.redone.source),
        (1, 2, 2, 0)
    );
    let after = read_manifest(&out).unwrap();
    check_manifest(&out, &after);
    for (a, b) in before.frames.iter().zip(&after.frames) {
        assert_eq!(a.checksum, b.checksum, "timestep {}", a.timestep);
    }
    // Nothing changed since: the next rerun reads nothing and keeps all.
    let r = batch(std::slice::from_ref(&set), &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped, r.kept_unchanged), (0, 3, 0));
    // One atom of the first frame moved in the second piece: that frame alone again.
    let mut text = whole[1].clone();
    let second = frame_starts(&text)[1];
    let digit = (second - 40..second)
        .find(|&i| text[i].is_ascii_digit() && text[i] != b'9')
        .unwrap();
    text[digit] += 1;
    std::fs::write(piece(1), &text).unwrap();
    let r = batch(std::slice::from_ref(&set), &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.kept_unchanged, r.redone.source), (1, 2, 1));
    // Binary pieces rewritten with the same bytes (a copy, a touch): every frame kept.
    for k in 0..2 {
        let from = lammps_sample_path(&format!("cu_melt_mpi.{k}.bin"));
        std::fs::copy(from, dir.path().join(format!("melt.{k}.bin"))).unwrap();
    }
    let bins = dir.path().join("melt.%.bin");
    let out = dir.path().join("bin");
    let r = batch(std::slice::from_ref(&bins), &out, &opts(), &NoProgress).unwrap();
    assert_eq!(r.converted, 3);
    for k in 0..2 {
        let p = dir.path().join(format!("melt.{k}.bin"));
        let bytes = std::fs::read(&p).unwrap();
        std::thread::sleep(std::time::Duration::from_millis(20));
        std::fs::write(&p, bytes).unwrap();
    }
    let r = batch(std::slice::from_ref(&bins), &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.kept_unchanged), (0, 3));
}

/// Per-processor pieces matched by a `*` (`melt.*.dump` matching `melt.0.dump` and
/// `melt.1.dump`) hold the same timesteps: the error names the `%` set to give first
/// (the way out of a restart, alone, kept half the atoms).
#[test]
fn pieces_given_as_files_are_named_as_a_set() {
    let dir = tempfile::tempdir().unwrap();
    let pieces: Vec<PathBuf> = (0..2)
        .map(|k| {
            let p = dir.path().join(format!("melt.{k}.dump"));
            std::fs::copy(lammps_sample_path(&format!("cu_melt_mpi.{k}.dump")), &p).unwrap();
            p
        })
        .collect();
    let e = batch(&pieces, &dir.path().join("o"), &opts(), &NoProgress).unwrap_err();
    let text = e.to_string();
    let set = dir.path().join("melt.%.dump");
    assert!(
        text.contains("pieces of one run written per processor")
            && text.contains(&format!("'{}'", set.display()))
            && text.contains("separate runs (replicas) go into batches of their own"),
        "{text}"
    );
    // As named, the set converts every atom of each frame.
    let r = batch(&[set], &dir.path().join("o"), &opts(), &NoProgress).unwrap();
    assert_eq!(r.converted, 3);
    let m = read_manifest(&dir.path().join("o")).unwrap();
    assert!(m.frames.iter().all(|f| f.particles == 500), "{m:?}");
}

/// LAMMPS's `dump.*.%.bin` (a file per timestep, each in pieces per processor): a quoted
/// pattern with both expands to one `%` set per timestep, every atom of each frame.
#[test]
fn a_pattern_with_a_star_and_a_percent_takes_a_piece_set_per_timestep() {
    let dir = tempfile::tempdir().unwrap();
    for k in 0..2 {
        let text =
            std::fs::read_to_string(lammps_sample_path(&format!("cu_melt_mpi.{k}.dump"))).unwrap();
        let frames: Vec<&str> = text
            .split("ITEM: TIMESTEP\n")
            .filter(|f| !f.is_empty())
            .collect();
        assert_eq!(frames.len(), 3);
        for f in frames {
            let step: u64 = f.lines().next().unwrap().trim().parse().unwrap();
            let name = dir.path().join(format!("melt.{step}.{k}.dump"));
            std::fs::write(name, format!("ITEM: TIMESTEP\n{f}")).unwrap();
        }
    }
    let out = dir.path().join("o");
    let inputs =
        mdlod_preprocess::batch::expand_patterns(&[dir.path().join("melt.*.%.dump")], &out)
            .unwrap();
    assert_eq!(inputs.len(), 3);
    let r = batch(&inputs, &out, &opts(), &NoProgress).unwrap();
    assert_eq!(r.converted, 3);
    let m = read_manifest(&out).unwrap();
    check_manifest(&out, &m);
    assert!(m.frames.iter().all(|f| f.particles == 500), "{m:?}");
    // The same frames as the `%` set of whole pieces.
    let whole = dir.path().join("whole");
    batch(
        &[lammps_sample_path("cu_melt_mpi.%.dump")],
        &whole,
        &opts(),
        &NoProgress,
    )
    .unwrap();
    let w = read_manifest(&whole).unwrap();
    let steps = |m: &Manifest| m.frames.iter().map(|f| f.timestep).collect::<Vec<_>>();
    assert_eq!(steps(&m), steps(&w));
    for (a, b) in m.frames.iter().zip(&w.frames) {
        let (fa, fb) = (
            MdlodFile::open(out.join(&a.file)).unwrap(),
            MdlodFile::open(whole.join(&b.file)).unwrap(),
        );
        assert_eq!(fa.nodes().len(), fb.nodes().len());
        assert_eq!(fa.metadata().simulation_box, fb.metadata().simulation_box);
        assert_eq!(format!("{:?}", fa.nodes()), format!("{:?}", fb.nodes()));
    }
}

/// A second run of one batch (of one shard of it) into a directory while the first
/// holds it is refused, naming the holder; other shards run beside it, and once the
/// holder ends (its lock goes with it, however it ends) the run goes ahead.
#[test]
fn a_second_run_of_the_same_shard_is_refused_while_the_first_runs() {
    use mdlod_preprocess::batch::lock_file_name;
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let out = dir.path().join("out");
    std::fs::create_dir(&out).unwrap();
    // Another process's lock, as a running batch holds it.
    let held = |shard: Option<(u32, u32)>| {
        let path = out.join(lock_file_name(shard));
        std::fs::write(&path, "pid 4242 on node17").unwrap();
        let f = std::fs::File::open(&path).unwrap();
        f.lock().unwrap();
        f
    };
    let first = held(None);
    let e = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap_err();
    assert!(matches!(e, BatchError::Busy { .. }), "{e}");
    let text = e.to_string();
    assert!(
        text.contains("another mdlod batch is writing this directory (pid 4242 on node17)"),
        "{text}"
    );
    assert!(!out.join("dataset.json").exists());
    drop(first);
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!(r.converted, 6);
    // Shards: the holder of shard 0 blocks shard 0 only.
    let out2 = dir.path().join("sharded");
    std::fs::create_dir(&out2).unwrap();
    let path = out2.join(lock_file_name(Some((0, 2))));
    std::fs::write(&path, "pid 7 on node3").unwrap();
    let f = std::fs::File::open(&path).unwrap();
    f.lock().unwrap();
    let e = batch(std::slice::from_ref(&src), &out2, &shard(0, 2), &NoProgress).unwrap_err();
    assert!(
        e.to_string()
            .contains("beside which this run (shard 0 of 2) must not"),
        "{e}"
    );
    let r = batch(std::slice::from_ref(&src), &out2, &shard(1, 2), &NoProgress).unwrap();
    assert_eq!(r.converted, 3);
    // A whole run beside a running shard (shards hold the whole run's lock together) is
    // refused, and a shard beside a running whole run.
    let whole = std::fs::File::open(out2.join(lock_file_name(None))).unwrap();
    whole.lock_shared().unwrap();
    let e = batch(std::slice::from_ref(&src), &out2, &opts(), &NoProgress).unwrap_err();
    assert!(
        e.to_string()
            .contains("is writing this directory (shards of it, which"),
        "{e}"
    );
    drop(whole);
    let first = held(None);
    let e = batch(std::slice::from_ref(&src), &out, &shard(1, 2), &NoProgress).unwrap_err();
    assert!(e.to_string().contains("(pid 4242 on node17)"), "{e}");
    drop(first);
}

fn read_manifest_at(path: &Path) -> Manifest {
    let text = std::fs::read(path).unwrap();
    mdlod_preprocess::batch::parse_manifest(path, &text, "shard").unwrap()
}

/// The sample trajectory as one file per timestep (`melt.<timestep>.dump`), as LAMMPS
/// writes a `dump.*.lammpstrj` set.
fn file_per_timestep(dir: &Path) -> Vec<PathBuf> {
    let text = std::fs::read_to_string(lammps_sample_path("cu_melt.custom.dump")).unwrap();
    // Each frame starts with its time; the first file's units head every file.
    let (units, frames) = text.split_once("ITEM: TIME\n").unwrap();
    std::iter::once(frames)
        .chain(text.split("ITEM: TIME\n").skip(2))
        .map(|frame| frame.split("ITEM: TIME\n").next().unwrap())
        .map(|frame| {
            let (_, rest) = frame.split_once("ITEM: TIMESTEP\n").unwrap();
            let timestep: u64 = rest.lines().next().unwrap().trim().parse().unwrap();
            let p = dir.join(format!("melt.{timestep}.dump"));
            std::fs::write(&p, format!("{units}ITEM: TIME\n{frame}")).unwrap();
            p
        })
        .collect()
}

fn listed(out: &Path) -> Vec<u64> {
    read_manifest(out)
        .unwrap()
        .frames
        .iter()
        .map(|f| f.timestep)
        .collect()
}

/// Users delete dumps once converted and add new ones: a rerun over the dumps left keeps
/// listing the frames of the deleted ones (their files are all that is left of them),
/// unless it asks for other settings, which it cannot convert them with.
#[test]
fn frames_of_deleted_dumps_stay_listed_when_built_with_this_runs_settings() {
    let dir = tempfile::tempdir().unwrap();
    let files = file_per_timestep(dir.path());
    let out = dir.path().join("out");
    let r = batch(&files[..4], &out, &opts(), &NoProgress).unwrap();
    assert_eq!(r.converted, 4);
    for f in &files[..2] {
        std::fs::remove_file(f).unwrap();
    }
    // The dumps left and two new ones.
    let r = batch(&files[2..], &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped), (2, 2));
    assert_eq!(r.kept_gone, [0, 100]);
    assert!(r.strays.is_empty() && r.gone_other.is_empty());
    let m = read_manifest(&out).unwrap();
    assert_eq!(listed(&out), [0, 100, 200, 300, 400, 500]);
    assert_eq!(m.expected_frames, Some(6));
    check_manifest(&out, &m);
    assert_eq!(
        verify_dir(&out, &NoProgress).unwrap().unlisted,
        Vec::<String>::new()
    );
    // A file whose dump still exists but is not given is another run's: named, not listed.
    let r = batch(&files[3..], &out, &opts(), &NoProgress).unwrap();
    assert_eq!(r.kept_gone, [0, 100]);
    assert_eq!(r.strays, ["frame-200.mdlod"]);
    assert_eq!(listed(&out), [0, 100, 300, 400, 500]);
    // Other radii: the dumps left convert again, the deleted ones' frames cannot.
    let mut other = opts();
    other.convert.radii = vec![("1".into(), 1.5)];
    let r = batch(&files[2..], &out, &other, &NoProgress).unwrap();
    assert!(r.kept_gone.is_empty());
    assert_eq!(r.gone_other, ["frame-0.mdlod", "frame-100.mdlod"]);
    assert_eq!(listed(&out), [200, 300, 400, 500]);
    assert!(out.join("frame-0.mdlod").exists());
    let check = verify_dir(&out, &NoProgress).unwrap();
    assert_eq!(check.kept_unlisted, ["frame-0.mdlod", "frame-100.mdlod"]);
    assert!(check.unlisted.is_empty(), "{:?}", check.unlisted);
    // Their records stay: back to the settings they were converted with, they are listed
    // again.
    let r = batch(&files[2..], &out, &opts(), &NoProgress).unwrap();
    assert_eq!(r.kept_gone, [0, 100]);
    assert_eq!(listed(&out), [0, 100, 200, 300, 400, 500]);
    // A frame file deleted with its dump: said once, and no longer listed.
    std::fs::remove_file(out.join("frame-0.mdlod")).unwrap();
    let r = batch(&files[2..], &out, &opts(), &NoProgress).unwrap();
    assert_eq!(
        (r.vanished.clone(), r.kept_gone.clone()),
        (vec![0], vec![100])
    );
    assert_eq!(listed(&out), [100, 200, 300, 400, 500]);
    let r = batch(&files[2..], &out, &opts(), &NoProgress).unwrap();
    assert!(r.vanished.is_empty());
}

/// In a sharded run every shard lists the deleted dumps' frames (the first to convert
/// removes the merged manifest, whose records the others would need), and the merge lists
/// each once.
#[test]
fn shards_list_the_frames_of_deleted_dumps_once_between_them() {
    let dir = tempfile::tempdir().unwrap();
    let files = file_per_timestep(dir.path());
    let out = dir.path().join("out");
    batch(&files[..3], &out, &opts(), &NoProgress).unwrap();
    for f in &files[..3] {
        std::fs::remove_file(f).unwrap();
    }
    let a = batch(&files[3..], &out, &shard(0, 2), &NoProgress).unwrap();
    let b = batch(&files[3..], &out, &shard(1, 2), &NoProgress).unwrap();
    assert_eq!(a.kept_gone, [0, 100, 200]);
    assert_eq!(b.kept_gone, [0, 100, 200]);
    assert!(!out.join("dataset.json").exists());
    // Kept apart from each shard's own frames, which it expects.
    let s0 = read_manifest_at(&out.join("dataset.shard-0-of-2.json"));
    assert_eq!(s0.frames.len(), 2);
    assert_eq!(s0.expected_frames, Some(2));
    assert_eq!(s0.gone.len(), 3);
    let m = merge(&out).unwrap();
    assert_eq!(
        m.frames.iter().map(|f| f.timestep).collect::<Vec<_>>(),
        [0, 100, 200, 300, 400, 500]
    );
    assert_eq!(m.expected_frames, Some(6));
    check_manifest(&out, &m);
}

/// A dump deleted between two shards' runs: the shard that converts first moves the
/// merged manifest aside, and the other still finds the record of the deleted dump's
/// frame there, so the merge lists every frame.
#[test]
fn a_dump_deleted_between_shard_runs_keeps_its_frame() {
    let dir = tempfile::tempdir().unwrap();
    let files = file_per_timestep(dir.path());
    let out = dir.path().join("out");
    batch(&files[..4], &out, &opts(), &NoProgress).unwrap();
    let r0 = batch(&files[..5], &out, &shard(0, 2), &NoProgress).unwrap();
    assert_eq!(r0.removed_merged, Some(out.join("dataset.json")));
    // Timestep 100 is shard 1's (the second of the list) and recorded only in the merged
    // manifest shard 0 moved aside.
    std::fs::remove_file(&files[1]).unwrap();
    let mut left = files[..5].to_vec();
    left.remove(1);
    let r1 = batch(&left, &out, &shard(1, 2), &NoProgress).unwrap();
    assert_eq!(r1.kept_gone, [100]);
    assert!(r1.gone_other.is_empty());
    // The shards saw different lists: shard 0 runs again over the inputs left.
    batch(&left, &out, &shard(0, 2), &NoProgress).unwrap();
    let m = merge(&out).unwrap();
    assert_eq!(
        m.frames.iter().map(|f| f.timestep).collect::<Vec<_>>(),
        [0, 100, 200, 300, 400]
    );
    assert_eq!(m.expected_frames, Some(5));
    check_manifest(&out, &m);
}

/// A frame converted again after the shards ran (a whole run with other settings killed
/// before it removed the shard manifests) is refused by the merge, which compares every
/// listed file's checksum, rather than listed with the shard's stale checksum.
#[test]
fn merge_refuses_a_frame_converted_again_since_its_shard_ran() {
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let out = dir.path().join("out");
    batch(std::slice::from_ref(&src), &out, &shard(0, 2), &NoProgress).unwrap();
    batch(std::slice::from_ref(&src), &out, &shard(1, 2), &NoProgress).unwrap();
    merge(&out).unwrap();
    let mut other = opts();
    other.convert.radii = vec![("1".into(), 1.5)];
    mdlod_preprocess::convert::convert_file(
        &src,
        &out.join("frame-200.mdlod"),
        mdlod_preprocess::convert::FrameSelect::Index(2),
        &other.read,
        &other.convert,
        &NoProgress,
    )
    .unwrap();
    let e = merge(&out).unwrap_err().to_string();
    assert!(
        e.contains("dataset.shard-0-of-2.json lists frame-200.mdlod with checksum")
            && e.contains("it was converted again since the shard ran"),
        "{e}"
    );
}

/// A dump written over under the same name (a restart into the same file) holds other
/// frames now: the frames converted from it before are those of a dump that is gone.
#[test]
fn frames_of_a_dump_written_over_stay_listed() {
    let dir = tempfile::tempdir().unwrap();
    let files = file_per_timestep(dir.path());
    let out = dir.path().join("out");
    batch(&files[..2], &out, &opts(), &NoProgress).unwrap();
    // melt.0.dump now holds timestep 500's frame.
    std::fs::copy(&files[5], &files[0]).unwrap();
    let r = batch(&files[..2], &out, &opts(), &NoProgress).unwrap();
    assert_eq!(r.kept_gone, [0]);
    assert_eq!(listed(&out), [0, 100, 500]);
}

/// Two runs' dumps of one name in two directories: a rerun over one of them takes the
/// other's frames for another run's (its dump is there, by the path recorded whole), not
/// for frames of a dump gone.
#[test]
fn a_dump_of_the_same_name_elsewhere_is_not_taken_for_gone() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(lammps_sample_path("cu_melt.custom.dump")).unwrap();
    let cut = text.match_indices("ITEM: TIME\n").nth(3).unwrap().0;
    let (run1, run2) = (dir.path().join("run1"), dir.path().join("run2"));
    std::fs::create_dir(&run1).unwrap();
    std::fs::create_dir(&run2).unwrap();
    let (a, b) = (run1.join("traj.dump"), run2.join("traj.dump"));
    std::fs::write(&a, &text[..cut]).unwrap();
    let units = &text[..text.find("ITEM: TIME\n").unwrap()];
    std::fs::write(&b, format!("{units}{}", &text[cut..])).unwrap();
    let out = dir.path().join("out");
    batch(&[a.clone(), b.clone()], &out, &opts(), &NoProgress).unwrap();
    assert_eq!(listed(&out), [0, 100, 200, 300, 400, 500]);
    let r = batch(std::slice::from_ref(&b), &out, &opts(), &NoProgress).unwrap();
    assert!(r.kept_gone.is_empty(), "{:?}", r.kept_gone);
    assert_eq!(r.strays.len(), 3);
    assert_eq!(listed(&out), [300, 400, 500]);
}

/// A reporter that replaces the input by another file under its name (as rsync does:
/// written beside it, renamed over it) once the conversions have begun.
struct ReplaceOnce {
    input: PathBuf,
    other: Vec<u8>,
    done: std::sync::atomic::AtomicBool,
}

impl mdlod_preprocess::Progress for ReplaceOnce {
    fn stage(&self, _name: &str, _total: Option<u64>, _unit: &'static str) {}
    fn advance(&self, _amount: u64) {
        if !self.done.swap(true, std::sync::atomic::Ordering::SeqCst) {
            let tmp = self.input.with_extension("new");
            std::fs::write(&tmp, &self.other).unwrap();
            std::fs::rename(&tmp, &self.input).unwrap();
        }
    }
}

/// An input replaced by another file under its name while a batch runs: the batch
/// converts the file it indexed (its mapping keeps those bytes) and records that file's
/// size and time, so a rerun finds every frame stale and converts the new file's. The
/// frames converted after the swap recorded the new file's size and time beside the old
/// data, and reruns (and `verify`) kept them.
#[test]
fn an_input_replaced_during_a_batch_leaves_no_frame_a_rerun_keeps() {
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let old = std::fs::read(&src).unwrap();
    // Another run's dump of the same timesteps: every x coordinate moved, a longer file.
    let text = String::from_utf8(old.clone()).unwrap();
    let other: String = text
        .lines()
        .map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            if f.len() > 4 && !l.starts_with("ITEM") && f[2].parse::<f64>().is_ok() {
                let x: f64 = f[2].parse().unwrap();
                let mut f: Vec<String> = f.iter().map(|s| s.to_string()).collect();
                f[2] = format!("{:.6}", x + 0.25);
                f.join(" ") + "\n"
            } else {
                l.to_string() + "\n"
            }
        })
        .collect();
    assert_ne!(other.len(), old.len());
    let out = dir.path().join("out");
    let swap = ReplaceOnce {
        input: src.clone(),
        other: other.clone().into_bytes(),
        done: false.into(),
    };
    batch(std::slice::from_ref(&src), &out, &opts(), &swap).unwrap();
    assert!(swap.done.load(std::sync::atomic::Ordering::SeqCst));
    let m = read_manifest(&out).unwrap();
    assert!(
        m.frames.iter().all(|f| f.source.size == old.len() as u64),
        "{m:?}"
    );
    // The rerun converts the new file's every frame, as a fresh batch does.
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!(r.converted, 6);
    let fresh = dir.path().join("fresh");
    batch(std::slice::from_ref(&src), &fresh, &opts(), &NoProgress).unwrap();
    let (a, b) = (read_manifest(&out).unwrap(), read_manifest(&fresh).unwrap());
    let sums = |m: &Manifest| {
        m.frames
            .iter()
            .map(|f| f.checksum.clone())
            .collect::<Vec<_>>()
    };
    assert_eq!(sums(&a), sums(&b));
}

/// The frame index is kept in the batch directory: a rerun lists text dumps unchanged
/// since from it (one changed is scanned again), `index_only` writes it and converts
/// nothing, and the shards of an array started after it scan no dump; every run lists
/// the same frames either way.
#[test]
fn text_dumps_are_scanned_once_across_reruns_and_shards() {
    let dir = tempfile::tempdir().unwrap();
    let set = file_set(&dir.path().join("src"));
    // (A dump modified or changed within two seconds of its scan is not kept.)
    let settle = || std::thread::sleep(std::time::Duration::from_millis(2100));
    let out = dir.path().join("out");
    // Written a moment ago, a dump is scanned by every run until it settles.
    let fresh = BatchOptions {
        index_only: true,
        ..opts()
    };
    let just_written = dir.path().join("fresh.dump");
    std::fs::copy(&set[0], &just_written).unwrap();
    for _ in 0..2 {
        let r = batch(
            std::slice::from_ref(&just_written),
            &dir.path().join("fresh.d"),
            &fresh,
            &NoProgress,
        )
        .unwrap();
        assert_eq!(
            (r.index.scanned, r.index.unsettled, r.index.from_cache),
            (1, 1, 0)
        );
    }
    settle();
    let index_only = BatchOptions {
        index_only: true,
        ..opts()
    };
    let r = batch(&set, &out, &index_only, &NoProgress).unwrap();
    assert_eq!(r.frames_total, set.len());
    assert_eq!(
        (r.converted, r.index.scanned, r.index.from_cache),
        (0, set.len(), 0)
    );
    assert!(out.join(INDEX_CACHE).is_file());
    assert!(
        !out.join("dataset.json").exists(),
        "nothing converted, no manifest"
    );
    assert_eq!(
        std::fs::read_dir(&out).unwrap().count(),
        1,
        "only the index is written"
    );
    // Indexed again: nothing to scan, nothing rewritten.
    let before = std::fs::metadata(out.join(INDEX_CACHE))
        .unwrap()
        .modified()
        .unwrap();
    let r = batch(&set, &out, &index_only, &NoProgress).unwrap();
    assert_eq!((r.index.scanned, r.index.from_cache), (0, set.len()));
    let after = std::fs::metadata(out.join(INDEX_CACHE))
        .unwrap()
        .modified()
        .unwrap();
    assert_eq!(before, after);

    let mut converted = 0;
    for i in 0..2 {
        let r = batch(&set, &out, &shard(i, 2), &NoProgress).unwrap();
        assert_eq!(
            (r.index.scanned, r.index.from_cache),
            (0, set.len()),
            "shard {i}"
        );
        converted += r.converted;
    }
    assert_eq!(converted, set.len());
    let merged = merge(&out).unwrap();
    assert_eq!(merged.frames.len(), set.len());

    // A dump rewritten since (its last frame's timestep changed): scanned again, and
    // its frame converted under its new timestep.
    let last = set.last().unwrap();
    let text = std::fs::read_to_string(last).unwrap();
    let step = text
        .split("ITEM: TIMESTEP\n")
        .nth(1)
        .unwrap()
        .lines()
        .next()
        .unwrap();
    let changed = text.replacen(
        &format!("ITEM: TIMESTEP\n{step}\n"),
        "ITEM: TIMESTEP\n777777\n",
        1,
    );
    std::fs::write(last, changed).unwrap();
    settle();
    let r = batch(&set, &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.index.scanned, r.index.from_cache), (1, set.len() - 1));
    assert_eq!(r.converted, 1, "{r:#?}");
    assert!(out.join("frame-777777.mdlod").is_file());
}

/// A dump listed from the index whose frame cannot be read is dropped from the index,
/// so that the next run scans it: an index at fault (two frames made one, which no check
/// short of a scan tells) costs one failed run, not every run after it. A large gzip
/// input, decompressed into a working file, keeps no index.
#[test]
fn a_frame_unread_from_an_indexed_dump_drops_the_dump_from_the_index() {
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    std::thread::sleep(std::time::Duration::from_millis(2100));
    let out = dir.path().join("out");
    let index_only = BatchOptions {
        index_only: true,
        ..opts()
    };
    batch(std::slice::from_ref(&src), &out, &index_only, &NoProgress).unwrap();
    let path = out.join(INDEX_CACHE);
    let mut index: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    let key = index["inputs"]
        .as_object()
        .unwrap()
        .keys()
        .next()
        .unwrap()
        .clone();
    let frames = &mut index["inputs"][&key]["frames"];
    // Frames 0 and 1 as one.
    frames["ranges"][0][1] = frames["ranges"][1][1].clone();
    frames["ranges"].as_array_mut().unwrap().remove(1);
    frames["timesteps"].as_array_mut().unwrap().remove(1);
    let keep = BatchOptions {
        keep_going: true,
        ..opts()
    };
    // Its checksum untrue, the altered entry is passed over.
    std::fs::write(&path, serde_json::to_vec(&index).unwrap()).unwrap();
    let r = batch(std::slice::from_ref(&src), &out, &index_only, &NoProgress).unwrap();
    assert_eq!((r.index.scanned, r.index.from_cache), (1, 0));
    // Its checksum made true again (as a writer at fault would write it), it passes
    // the checks of the ranges.
    let entry = &mut index["inputs"][&key];
    let check = mdlod_preprocess::readers::index_cache::entry_checksum(
        &entry["identity"],
        &entry["frames"],
    );
    entry["check"] = check.into();
    std::fs::write(&path, serde_json::to_vec(&index).unwrap()).unwrap();

    let r = batch(std::slice::from_ref(&src), &out, &keep, &NoProgress).unwrap();
    assert_eq!(r.index.from_cache, 1, "the altered entry passes the checks");
    assert_eq!(r.failed.len(), 1, "{:?}", r.failed);
    let index: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    assert!(index["inputs"].as_object().unwrap().is_empty(), "{index}");
    let r = batch(std::slice::from_ref(&src), &out, &keep, &NoProgress).unwrap();
    assert_eq!((r.index.scanned, r.index.from_cache), (1, 0));
    assert!(r.failed.is_empty(), "{:?}", r.failed);
    assert_eq!(read_manifest(&out).unwrap().frames.len(), 6);

    // A gzip input decompressed into a working file: nothing kept.
    let gz = dir.path().join("melt.dump.gz");
    std::fs::copy(lammps_sample_path("cu_melt.custom.dump.gz"), &gz).unwrap();
    let mut spool = index_only.clone();
    spool.convert.chunks.gzip_in_memory = Some(0);
    let gz_out = dir.path().join("gz");
    let r = batch(std::slice::from_ref(&gz), &gz_out, &spool, &NoProgress).unwrap();
    assert_eq!(r.frames_total, 6);
    assert_eq!(
        (r.index.scanned, r.index.from_cache, r.index.not_kept),
        (0, 0, 1)
    );
    assert!(!gz_out.join(INDEX_CACHE).exists());
}

/// A frame file cut short (a copy that stopped, a disk that filled) or whose top level's
/// node records are damaged does not open as complete: a rerun converts it again, and
/// leaves the others as they were.
#[test]
fn a_rerun_converts_again_a_frame_file_cut_short_or_damaged() {
    let dir = tempfile::tempdir().unwrap();
    let src = input(dir.path());
    let out = dir.path().join("out");
    batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    let manifest = read_manifest(&out).unwrap();
    let (cut, damaged) = (&manifest.frames[1].file, &manifest.frames[3].file);
    let len = std::fs::metadata(out.join(cut)).unwrap().len();
    std::fs::OpenOptions::new()
        .write(true)
        .open(out.join(cut))
        .unwrap()
        .set_len(len / 2)
        .unwrap();
    // The top node's record: its bounds made NaN.
    let f = MdlodFile::open(out.join(damaged)).unwrap();
    let at = f.sections().iter().find(|e| e.kind == 3).unwrap().offset;
    drop(f);
    let mut bytes = std::fs::read(out.join(damaged)).unwrap();
    bytes[at as usize..at as usize + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    std::fs::write(out.join(damaged), bytes).unwrap();
    let r = batch(std::slice::from_ref(&src), &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped), (2, 4), "{r:?}");
    for f in &read_manifest(&out).unwrap().frames {
        MdlodFile::open(out.join(&f.file))
            .unwrap()
            .verify()
            .unwrap();
    }
}

/// A `dump.*` set whose first file alone records `ITEM: UNITS` (LAMMPS writes it once
/// per dump command): every frame of the set keeps those units, built whole or in
/// chunks; a later file recording its own keeps them.
#[test]
fn a_file_sets_units_carry_to_its_later_files() {
    let dir = tempfile::tempdir().unwrap();
    let file = |step: u64, units: Option<&str>| {
        let head = units.map_or(String::new(), |u| format!("ITEM: UNITS\n{u}\n"));
        let mut text = format!(
            "{head}ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ATOMS\n40\nITEM: BOX BOUNDS pp pp \
             pp\n0 4\n0 4\n0 4\nITEM: ATOMS id type x y z\n"
        );
        for i in 0..40 {
            text.push_str(&format!("{} 1 {} {} 0.5\n", i + 1, i % 4, i / 4 % 4));
        }
        let path = dir.path().join(format!("dump.{step}.lammpstrj"));
        std::fs::write(&path, text).unwrap();
        path
    };
    let inputs = vec![
        file(0, Some("metal")),
        file(100, None),
        file(200, None),
        file(300, Some("real")),
        file(400, None),
    ];
    for chunk_points in [1 << 20, 16] {
        let out = dir.path().join(format!("out-{chunk_points}"));
        let mut o = opts();
        o.convert.chunks.chunk_points = chunk_points;
        o.convert.build.max_root_points = 8;
        batch(&inputs, &out, &o, &NoProgress).unwrap();
        let m = read_manifest(&out).unwrap();
        let units: Vec<Option<String>> = m
            .frames
            .iter()
            .map(|f| {
                let file = MdlodFile::open(out.join(&f.file)).unwrap();
                file.metadata().units.clone()
            })
            .collect();
        assert_eq!(
            units,
            ["metal", "metal", "metal", "real", "real"].map(|u| Some(u.to_string())),
            "chunks of {chunk_points}"
        );
    }
}

/// A batch directory reused for another run's dumps (`-o` given again), or inputs
/// numbered by their place of which one was left out, would have frames replaced by
/// other data with a note only: refused while the inputs the frames came from are still
/// there, converted again once they are gone (dumps moved, or deleted once converted).
#[test]
fn frames_of_other_inputs_still_there_are_not_replaced() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    std::fs::create_dir_all(&a).unwrap();
    std::fs::create_dir_all(&b).unwrap();
    let first = input(&a);
    // Another run's dump of the same timesteps, of the same name, one digit apart.
    let mut other = std::fs::read(&first).unwrap();
    let digit = (other.len() / 2..other.len())
        .find(|&i| other[i] == b'1')
        .unwrap();
    other[digit] = b'2';
    let second = b.join("melt.dump");
    std::fs::write(&second, &other).unwrap();
    // (Written a second later: two files written within one tick of the clock would
    // share name, size and time, and be taken for one file moved.)
    let f = std::fs::File::options().write(true).open(&second).unwrap();
    f.set_modified(std::time::SystemTime::now() + std::time::Duration::from_secs(1))
        .unwrap();
    drop(f);
    let out = dir.path().join("out");
    batch(std::slice::from_ref(&first), &out, &opts(), &NoProgress).unwrap();
    let before = read_manifest(&out).unwrap();
    let e = batch(std::slice::from_ref(&second), &out, &opts(), &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("holds timestep") && e.contains("a/melt.dump, which is still there"),
        "{e}"
    );
    assert!(e.contains("frame ") && e.contains("b/melt.dump"), "{e}");
    assert_eq!(read_manifest(&out).unwrap(), before, "nothing replaced");
    // The first run's dump gone: its frames are converted again from the one given.
    std::fs::remove_file(&first).unwrap();
    let r = batch(std::slice::from_ref(&second), &out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.redone.source), (1, 1), "{r:?}");

    // Inputs numbered by their place: the first left out would shift the others.
    let xyz: Vec<PathBuf> = (0..3)
        .map(|i| {
            let p = dir.path().join(format!("s.{i}.xyz"));
            std::fs::write(&p, format!("2\nframe {i}\nC 0 0 {i}\nC 1 0 0\n")).unwrap();
            p
        })
        .collect();
    let xyz_out = dir.path().join("xyz");
    batch(&xyz, &xyz_out, &opts(), &NoProgress).unwrap();
    std::fs::rename(&xyz[0], dir.path().join("elsewhere.xyz")).unwrap();
    let e = batch(&xyz[1..], &xyz_out, &opts(), &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("frame-1.mdlod holds timestep 1 of")
            && e.contains("s.1.xyz, which is still there")
            && e.contains("frame 0 of")
            && e.contains("numbered by their place"),
        "{e}"
    );
    // Given back, nothing is converted again.
    std::fs::rename(dir.path().join("elsewhere.xyz"), &xyz[0]).unwrap();
    let r = batch(&xyz, &xyz_out, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.skipped), (0, 3));

    // A restart into a file of its own, its repeated timesteps taken from it: the frames
    // of the first file, one of this run's inputs, are replaced as asked.
    let run = dir.path().join("run");
    std::fs::create_dir_all(&run).unwrap();
    let first = input(&run);
    let text = std::fs::read_to_string(&first).unwrap();
    let from = text.find("ITEM: TIMESTEP\n400\n").unwrap();
    let restart = run.join("restart.dump");
    std::fs::write(&restart, text[from..].replacen(" 1 ", " 2 ", 1)).unwrap();
    let run_out = dir.path().join("run_out");
    batch(std::slice::from_ref(&first), &run_out, &opts(), &NoProgress).unwrap();
    let last = BatchOptions {
        duplicates: mdlod_preprocess::batch::Duplicates::Last,
        ..opts()
    };
    let r = batch(
        &[first.clone(), restart.clone()],
        &run_out,
        &last,
        &NoProgress,
    )
    .unwrap();
    assert_eq!(r.redone.source, 2, "{r:?}");
    // A restart superseding every frame of an earlier input (one file per timestep).
    let set = file_set(&run.join("set"));
    let sets = dir.path().join("sets");
    batch(&set, &sets, &opts(), &NoProgress).unwrap();
    let with_restart: Vec<PathBuf> = set.iter().cloned().chain([restart]).collect();
    let r = batch(&with_restart, &sets, &last, &NoProgress).unwrap();
    assert_eq!(r.redone.source, 2, "{r:?}");
    // The same bytes under another name (a copy, a hard link): kept, not refused.
    let copies = dir.path().join("copies");
    batch(std::slice::from_ref(&first), &copies, &opts(), &NoProgress).unwrap();
    let copy = run.join("copy.dump");
    std::fs::copy(&first, &copy).unwrap();
    let r = batch(std::slice::from_ref(&copy), &copies, &opts(), &NoProgress).unwrap();
    assert_eq!((r.converted, r.kept_unchanged), (0, 6), "{r:?}");
    let linked = run.join("linked.dump");
    std::fs::hard_link(&first, &linked).unwrap();
    let r = batch(std::slice::from_ref(&linked), &copies, &opts(), &NoProgress).unwrap();
    assert_eq!(r.converted, 0, "{r:?}");

    // Dumps copied elsewhere without their times (`cp`, not `cp -p`), the originals
    // still there: the same data, converted again, not refused.
    let gz = dir.path().join("gz");
    let copy = dir.path().join("copy");
    std::fs::create_dir_all(&gz).unwrap();
    std::fs::create_dir_all(&copy).unwrap();
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    std::io::Write::write_all(&mut enc, &std::fs::read(&first).unwrap()).unwrap();
    let packed = enc.finish().unwrap();
    std::fs::write(gz.join("melt.dump.gz"), &packed).unwrap();
    let gz_out = dir.path().join("gz_out");
    batch(&[gz.join("melt.dump.gz")], &gz_out, &opts(), &NoProgress).unwrap();
    std::fs::write(copy.join("melt.dump.gz"), &packed).unwrap();
    let f = std::fs::File::options()
        .write(true)
        .open(copy.join("melt.dump.gz"))
        .unwrap();
    f.set_modified(std::time::SystemTime::now() + std::time::Duration::from_secs(2))
        .unwrap();
    drop(f);
    batch(&[copy.join("melt.dump.gz")], &gz_out, &opts(), &NoProgress).unwrap();

    // A frame file made read-only that is to be replaced is refused before any frame is
    // converted.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let frame = gz_out.join("frame-500.mdlod");
        std::fs::set_permissions(&frame, std::fs::Permissions::from_mode(0o444)).unwrap();
        std::fs::remove_file(gz_out.join("frame-0.mdlod")).unwrap();
        let mut coarser = opts();
        coarser.convert.build.position_bits = 8;
        let e = batch(&[copy.join("melt.dump.gz")], &gz_out, &coarser, &NoProgress)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("frame-500.mdlod") && e.contains("read-only"),
            "{e}"
        );
        assert!(
            !gz_out.join("frame-0.mdlod").exists(),
            "no frame converted first"
        );
    }
}

/// A binary dump of a set cut inside its frame's chunks fails with `--keep-going` under
/// its own timestep, which its header gives (it was listed by its place among the
/// inputs, timestep 1 for 250, so a script rerunning by timestep was misled).
#[test]
fn a_binary_frame_cut_inside_its_chunks_fails_under_its_own_timestep() {
    let dir = tempfile::tempdir().unwrap();
    let inputs: Vec<PathBuf> = [0, 250, 500]
        .iter()
        .map(|t| {
            let p = dir.path().join(format!("cu.{t}.bin"));
            std::fs::copy(lammps_sample_path(&format!("cu_melt.step.{t}.bin")), &p).unwrap();
            p
        })
        .collect();
    let f = std::fs::File::options()
        .write(true)
        .open(&inputs[1])
        .unwrap();
    f.set_len(5000).unwrap();
    drop(f);
    let out = dir.path().join("out");
    let keep_going = BatchOptions {
        keep_going: true,
        ..opts()
    };
    let r = batch(&inputs, &out, &keep_going, &NoProgress).unwrap();
    assert_eq!(r.converted, 2);
    assert_eq!(r.failed.len(), 1, "{:?}", r.failed);
    assert_eq!(
        (r.failed[0].timestep, r.failed[0].listed_timestep),
        (Some(250), Some(250))
    );
    let m = read_manifest(&out).unwrap();
    assert_eq!(
        m.failed.iter().map(|f| f.timestep).collect::<Vec<_>>(),
        [Some(250)]
    );
}
