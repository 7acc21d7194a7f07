//! Frame indexes kept between runs (`readers::index_cache`): a text dump unchanged since it
//! was scanned is listed from the cache exactly as a scan lists it; a changed file, a
//! damaged or hostile cache, are scanned again.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use mdlod_datasets::lammps_sample_path;
use mdlod_preprocess::readers::index_cache::IndexCache;
use mdlod_preprocess::readers::{DumpFile, ReadOptions};
use mdlod_preprocess::NoProgress;

/// One frame as listed: timestep, byte range, header, particles read (or the errors).
type Listed = (Option<u64>, Option<std::ops::Range<u64>>, String, String);

/// Everything a listing gives of each frame: timestep, byte range, header, and the
/// particles read.
fn listing(path: &Path) -> Vec<Listed> {
    let dump = DumpFile::open(path).unwrap();
    (0..dump.frame_count())
        .map(|k| {
            let frame = dump.read_frame(k, &ReadOptions::default(), &NoProgress);
            (
                dump.frame_timestep(k),
                dump.frame_bytes(k),
                format!("{:?}", dump.frame_info(k)),
                match frame {
                    Ok(f) => f.positions.len().to_string(),
                    Err(e) => e.to_string(),
                },
            )
        })
        .collect()
}

/// [`listing`] of `path` with `cache` in scope.
fn listing_with(cache: &Arc<IndexCache>, path: &Path) -> Vec<Listed> {
    let _scope = cache.scope();
    listing(path)
}

/// Waits until the files written before have settled: a file modified or changed
/// within two seconds of its scan is not kept (its change time cannot be set back).
fn settle() {
    std::thread::sleep(std::time::Duration::from_millis(2100));
}

/// Sets `path`'s modification time `offset` seconds from now (its change time becomes
/// now).
fn touch(path: &Path, offset: i64) {
    let now = std::time::SystemTime::now();
    let d = std::time::Duration::from_secs(offset.unsigned_abs());
    let t = if offset < 0 { now - d } else { now + d };
    let f = std::fs::File::options().write(true).open(path).unwrap();
    f.set_modified(t).unwrap();
}

fn copy(dir: &Path, sample: &str) -> PathBuf {
    let p = dir.join(sample);
    std::fs::copy(lammps_sample_path(sample), &p).unwrap();
    p
}

#[test]
fn unchanged_text_dumps_are_listed_from_the_cache_as_a_scan_lists_them() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("index.json");
    // A dump that ends in the first lines of a frame's header (a run writing it) lists
    // that frame too, cut short.
    let cut = dir.path().join("cut.dump");
    let mut text = std::fs::read(lammps_sample_path("cu_melt.custom.dump")).unwrap();
    text.extend_from_slice(b"ITEM: TIME\n1.5\nITEM: TIMES");
    std::fs::write(&cut, text).unwrap();
    copy(dir.path(), "cu_melt.custom.dump");
    copy(dir.path(), "cu_melt.xyz");
    settle();
    for sample in ["cu_melt.custom.dump", "cu_melt.xyz", "cut.dump"] {
        let input = dir.path().join(sample);
        let scanned = listing(&input);
        assert!(scanned.len() > 1, "{sample}: {} frames", scanned.len());

        let first = Arc::new(IndexCache::load(&file));
        assert_eq!(listing_with(&first, &input), scanned, "{sample}");
        assert_eq!((first.hits(), first.scanned()), (0, 1), "{sample}");
        first.save().unwrap();

        let second = Arc::new(IndexCache::load(&file));
        assert_eq!(listing_with(&second, &input), scanned, "{sample}");
        assert_eq!((second.hits(), second.scanned()), (1, 0), "{sample}");
        assert!(!second.changed(), "{sample}: nothing new to write");
    }
}

#[test]
fn a_changed_file_is_scanned_again() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("index.json");
    let input = copy(dir.path(), "cu_melt.custom.dump");
    let run = |expect: (usize, usize, usize), what: &str| {
        let cache = Arc::new(IndexCache::load(&file));
        let listed = listing_with(&cache, &input);
        assert_eq!(listed, listing(&input), "{what}");
        assert_eq!(
            (cache.hits(), cache.scanned(), cache.unsettled()),
            expect,
            "{what}: (from the cache, scanned, scanned and not kept)"
        );
        cache.save().unwrap();
        listed
    };
    run((0, 1, 1), "written a moment ago: scanned, not kept");
    settle();
    run((0, 1, 0), "settled: scanned and kept");
    run((1, 0, 0), "unchanged: from the cache");

    // A simulation appends a frame: the new one is listed.
    let text = std::fs::read_to_string(&input).unwrap();
    let last = text.rfind("ITEM: TIMESTEP").unwrap();
    let appended = text[last..].replacen(
        &format!("ITEM: TIMESTEP\n{}", text[last..].lines().nth(1).unwrap()),
        "ITEM: TIMESTEP\n999999",
        1,
    );
    let mut f = std::fs::OpenOptions::new()
        .append(true)
        .open(&input)
        .unwrap();
    std::io::Write::write_all(&mut f, appended.as_bytes()).unwrap();
    drop(f);
    settle();
    let listed = run((0, 1, 0), "appended");
    assert_eq!(listed.last().unwrap().0, Some(999_999));
    run((1, 0, 0), "unchanged since");

    // Touched (same bytes, an older time; its change time now): scanned again, and not
    // kept until the change has settled.
    touch(&input, -86_400);
    run((0, 1, 1), "touched");
    settle();
    run((0, 1, 0), "touched, settled");
    run((1, 0, 0), "unchanged since");

    // Its permissions changed (the change time alone): scanned again.
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&input, std::fs::Permissions::from_mode(0o640)).unwrap();
    settle();
    run((0, 1, 0), "status changed");

    // Dated ahead of this machine's clock (a file server's clock ahead): never kept.
    touch(&input, 3600);
    settle();
    run((0, 1, 1), "dated ahead");
    run((0, 1, 1), "dated ahead, again");
}

/// A cache file that is not one, or whose ranges do not fit the file they name, is
/// passed over: the input is scanned and listed as without a cache, never misread.
#[test]
fn damaged_or_hostile_caches_are_passed_over() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("index.json");
    copy(dir.path(), "cu_melt.custom.dump");
    copy(dir.path(), "cu_melt.xyz");
    settle();
    for sample in ["cu_melt.custom.dump", "cu_melt.xyz"] {
        let input = dir.path().join(sample);
        let truth = listing(&input);
        let cache = Arc::new(IndexCache::load(&file));
        listing_with(&cache, &input);
        cache.save().unwrap();
        let good: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&file).unwrap()).unwrap();
        let key = good["inputs"]
            .as_object()
            .unwrap()
            .keys()
            .find(|k| k.ends_with(sample))
            .unwrap()
            .clone();

        let mut hostile: Vec<(&str, Vec<u8>)> = vec![
            (
                "not JSON",
                b"{\"mdlod_frame_index\": 1, \"inputs\": {".to_vec(),
            ),
            ("another version", {
                let mut v = good.clone();
                v["mdlod_frame_index"] = 99.into();
                serde_json::to_vec(&v).unwrap()
            }),
        ];
        // A frame hidden in the range of the one before it (the last range widened to
        // the file's end): every range still starts with its header, and only the
        // entry's checksum tells (a batch took the hidden frame for one gone with its
        // dump, and `verify` agreed).
        hostile.push(("the last frame hidden in the range before it", {
            let mut v = good.clone();
            let f = &mut v["inputs"][&key]["frames"];
            let n = f["ranges"].as_array().unwrap().len();
            f["ranges"][n - 2][1] = f["ranges"][n - 1][1].clone();
            f["ranges"].as_array_mut().unwrap().pop();
            f["timesteps"].as_array_mut().unwrap().pop();
            serde_json::to_vec(&v).unwrap()
        }));
        // The edits below keep the checksum true, so that the checks of the ranges
        // themselves are what passes them over.
        let mut edit = |what: &'static str, f: &dyn Fn(&mut serde_json::Value)| {
            let mut v = good.clone();
            let entry = &mut v["inputs"][&key];
            f(&mut entry["frames"]);
            let check = mdlod_preprocess::readers::index_cache::entry_checksum(
                &entry["identity"],
                &entry["frames"],
            );
            entry["check"] = check.into();
            hostile.push((what, serde_json::to_vec(&v).unwrap()));
        };
        edit("a range starting mid-line", &|f| {
            f["ranges"][1][0] = (f["ranges"][1][0].as_u64().unwrap() + 3).into();
        });
        edit("a range past the end", &|f| {
            let n = f["ranges"].as_array().unwrap().len();
            f["ranges"][n - 1][1] = u64::MAX.into();
        });
        edit("ranges out of order", &|f| {
            f["ranges"].as_array_mut().unwrap().swap(0, 1);
        });
        edit("fewer timesteps than ranges", &|f| {
            f["timesteps"].as_array_mut().unwrap().pop();
        });
        edit("no frames", &|f| {
            f["ranges"] = serde_json::json!([]);
            f["timesteps"] = serde_json::json!([]);
        });
        edit("another format", &|f| {
            f["format"] = if sample.ends_with(".xyz") {
                "lammps"
            } else {
                "xyz"
            }
            .into();
        });
        edit("a timestep the frame does not hold", &|f| {
            f["timesteps"][1] = 123_456_789u64.into();
        });
        edit("two timesteps swapped", &|f| {
            f["timesteps"].as_array_mut().unwrap().swap(0, 1);
        });
        edit("no timestep for a frame that has one", &|f| {
            f["timesteps"][1] = serde_json::Value::Null;
        });
        edit("a range starting at another header line", &|f| {
            // The frame's second line onwards: an `ITEM:` line of the LAMMPS header, or
            // an XYZ frame's comment line.
            let start = f["ranges"][1][0].as_u64().unwrap() as usize;
            let text = std::fs::read(lammps_sample_path(sample)).unwrap();
            let next = start + text[start..].iter().position(|&b| b == b'\n').unwrap() + 1;
            f["ranges"][1][0] = (next as u64).into();
            f["ranges"][0][1] = (next as u64).into();
        });
        if !sample.ends_with(".xyz") {
            edit("a range starting past its frame's TIME lines", &|f| {
                let start = f["ranges"][1][0].as_u64().unwrap() as usize;
                let text = std::fs::read(lammps_sample_path(sample)).unwrap();
                let at = start
                    + text[start..]
                        .windows(14)
                        .position(|w| w == b"ITEM: TIMESTEP")
                        .unwrap();
                assert!(at > start, "frame 1 starts with its TIME lines");
                f["ranges"][1][0] = (at as u64).into();
                f["ranges"][0][1] = (at as u64).into();
            });
        }
        edit("an unread timestep of no frame", &|f| {
            f["unread_timesteps"] = serde_json::json!([[1000, "x"]]);
        });
        for (what, bytes) in hostile {
            std::fs::write(&file, bytes).unwrap();
            let cache = Arc::new(IndexCache::load(&file));
            assert_eq!(listing_with(&cache, &input), truth, "{sample}: {what}");
            assert_eq!((cache.hits(), cache.scanned()), (0, 1), "{sample}: {what}");
            // Saved again, the cache holds the scan's index.
            cache.save().unwrap();
            let again = Arc::new(IndexCache::load(&file));
            listing_with(&again, &input);
            assert_eq!(again.hits(), 1, "{sample}: {what}");
        }
        std::fs::remove_file(&file).unwrap();
    }
}

/// Compressed inputs are not kept (their text is decompressed to be read anyway), and
/// the cache is consulted only inside its scope.
#[test]
fn compressed_inputs_and_readers_outside_the_scope_leave_the_cache_alone() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("index.json");
    let gz = copy(dir.path(), "cu_melt.custom.dump.gz");
    let cache = Arc::new(IndexCache::load(&file));
    listing_with(&cache, &gz);
    assert_eq!((cache.hits(), cache.scanned()), (0, 0));
    let plain = copy(dir.path(), "cu_melt.custom.dump");
    {
        let _scope = cache.scope();
    }
    listing(&plain);
    assert_eq!((cache.hits(), cache.scanned()), (0, 0));
    assert!(!cache.changed());
}
