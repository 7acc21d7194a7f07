//! Hierarchy round trips: build, write, reopen, verify, and check the invariants the
//! renderer relies on.

use mdlod_format::quantize;
use mdlod_format::MdlodFile;
use mdlod_preprocess::chunked::ChunkOptions;
use mdlod_preprocess::convert::{convert_frame, ConvertOptions};
use mdlod_preprocess::hierarchy::BuildParams;
use mdlod_preprocess::{Attribute, Frame, NoProgress, SpeciesName};

/// A small deterministic frame: an FCC slab, a duplicated point pair, a sparse cloud.
fn test_frame(n_cells: usize) -> Frame {
    let (nz, ny) = (n_cells / 2, n_cells);
    let mut positions = mdlod_datasets::fcc_block([n_cells, n_cells, nz], 3.615);
    // Species by unit cell (i, j, k): site s lies in cell s / 4, k innermost.
    let mut species_index: Vec<u16> = (0..positions.len())
        .map(|s| {
            let c = s / 4;
            let (i, j, k) = (c / (nz * ny), (c / nz) % ny, c % nz);
            u16::from((i + j + k) % 7 == 0)
        })
        .collect();
    // Exact duplicates.
    for _ in 0..50 {
        positions.push([1.0, 1.0, 100.0]);
        species_index.push(0);
    }
    // A sparse cloud above (xorshift).
    let mut s = 0x9E3779B97F4A7C15u64;
    for _ in 0..500 {
        let mut r = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        positions.push([r() * 100.0, r() * 100.0, 50.0 + r() * 80.0]);
        species_index.push(1);
    }
    let values = positions.iter().map(|p| p[2] * 0.5 - 3.0).collect();
    Frame {
        species_index,
        species: vec![
            SpeciesName {
                name: "Cu".into(),
                numeric_type: false,
                radius: None,
                ..Default::default()
            },
            SpeciesName {
                name: "Ag".into(),
                numeric_type: false,
                radius: None,
                ..Default::default()
            },
        ],
        attribute: Some(Attribute {
            name: "c_pe".into(),
            values,
        }),
        timestep: Some(1000),
        positions,
        ..Default::default()
    }
}

fn convert(frame: &Frame, params: BuildParams) -> (tempfile::TempDir, MdlodFile) {
    convert_with(
        frame,
        &ConvertOptions {
            build: params,
            ..Default::default()
        },
    )
}

fn convert_with(frame: &Frame, opts: &ConvertOptions) -> (tempfile::TempDir, MdlodFile) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.mdlod");
    convert_frame(frame, None, &path, opts, &NoProgress).unwrap();
    let f = MdlodFile::open(&path).unwrap();
    (dir, f)
}

/// Options that build `frame` in chunks of at most `chunk_points`.
fn chunked(params: BuildParams, chunk_points: usize, memory_limit: u64) -> ConvertOptions {
    ConvertOptions {
        build: params,
        chunks: ChunkOptions {
            chunk_points,
            memory_limit,
            temp_dir: None,
            window_points: 128,
            gzip_in_memory: None,
        },
        ..Default::default()
    }
}

fn check_round_trip(frame: &Frame, params: BuildParams) {
    check_round_trip_with(
        frame,
        &ConvertOptions {
            build: params,
            ..Default::default()
        },
    );
}

fn check_round_trip_with(frame: &Frame, opts: &ConvertOptions) {
    let params = opts.build.clone();
    let (dir, f) = convert_with(frame, opts);
    let chunked = frame.len() > opts.chunks.chunk_points;
    assert_eq!(
        f.metadata().build.chunk_points,
        chunked.then_some(opts.chunks.chunk_points as u64)
    );
    // Working files are gone.
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left, vec![std::ffi::OsString::from("t.mdlod")]);
    let report = f.verify().unwrap();
    let last = f.level_count() - 1;
    assert_eq!(f.particle_count() as usize, frame.len());
    assert_eq!(
        report.points_decoded as usize,
        f.levels()[1..]
            .iter()
            .map(|l| l.point_count as usize)
            .sum::<usize>()
    );

    // Every particle decodes within the recorded bound, and the bound is honest:
    // within the theoretical half step of its encoding node.
    let decoded = f.decode_level(last).unwrap();
    let bound = f.metadata().max_position_error;
    // Match decoded particles to inputs: same multiset of (species, position within bound).
    // The file keeps no particle ids, so compare sorted by a spatial key of the input
    // positions via the species counts and a nearest check on a grid.
    let mut species_counts = [0usize; 2];
    for &s in f.species() {
        species_counts[s as usize] += 1;
    }
    let mut input_counts = [0usize; 2];
    for &s in &frame.species_index {
        input_counts[s as usize] += 1;
    }
    assert_eq!(species_counts, input_counts);
    let mut grid = std::collections::HashMap::<[i64; 3], Vec<([f32; 3], usize)>>::new();
    let cell = 2.0f32;
    let key = |p: [f32; 3]| p.map(|v| (v / cell).floor() as i64);
    for (j, p) in frame.positions.iter().enumerate() {
        grid.entry(key(*p)).or_default().push((*p, j));
    }
    // Each particle keeps its own species and attribute: those of the input nearest to
    // where it decodes (the file reorders particles; per-particle data must follow).
    let info = f.metadata().attribute.clone().unwrap();
    let attribute = f.attribute().unwrap();
    let inputs = frame.attribute.as_ref().unwrap();
    let attribute_step = (info.max - info.min) / 65535.0;
    let mut worst = 0.0f64;
    for (i, d) in decoded.iter().enumerate() {
        let k = key(*d);
        let mut best = f64::INFINITY;
        let mut nearest = usize::MAX;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(v) = grid.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) {
                        for (p, j) in v {
                            let e: f64 = (0..3)
                                .map(|c| (f64::from(p[c]) - f64::from(d[c])).powi(2))
                                .sum();
                            if e.sqrt() < best {
                                (best, nearest) = (e.sqrt(), *j);
                            }
                        }
                    }
                }
            }
        }
        worst = worst.max(best);
        if nearest != usize::MAX {
            assert_eq!(
                f.species()[i],
                frame.species_index[nearest],
                "particle {i} (input {nearest}): species"
            );
            let value = info.decode(attribute[i]);
            assert!(
                (value - inputs.values[nearest]).abs() <= attribute_step,
                "particle {i} (input {nearest}): attribute {value} for {}",
                inputs.values[nearest]
            );
        }
    }
    assert!(
        worst <= bound + 1e-12,
        "a particle decodes {worst} away, recorded bound {bound}"
    );
    let h = quantize::half_range(params.position_bits) as f64;
    let extent = 130.0 * 3f64.sqrt();
    assert!(
        bound <= extent / h,
        "bound {bound} exceeds a half step of the whole extent"
    );

    // Hierarchy invariants and Eq. 1 per cluster.
    let nodes = f.nodes();
    let levels = f.levels();
    assert_eq!(levels[0].point_count, 1);
    for l in 0..last {
        for (i, n) in f.level_nodes(l).iter().enumerate() {
            let id = levels[l].node_first as usize + i;
            // Area (flux) is conserved: Σ children's area = parent's area.
            let child_area: f64 = if l + 1 < last {
                f.level_nodes(l + 1)
                    [n.child_first as usize..(n.child_first + n.child_count) as usize]
                    .iter()
                    .map(|c| f64::from(c.area_sum))
                    .sum()
            } else {
                let sp = f.species();
                let order_species =
                    &sp[n.child_first as usize..(n.child_first + n.child_count) as usize];
                order_species
                    .iter()
                    .map(|&s| f64::from(f.metadata().species[s as usize].radius).powi(2))
                    .sum()
            };
            let rel = (child_area - f64::from(n.area_sum)).abs() / child_area;
            assert!(
                rel < 1e-5,
                "node {id}: area {} vs children {child_area}",
                n.area_sum
            );
            // Eq. 2: never smaller than the largest child.
            let largest_child = if l + 1 < last {
                f.level_nodes(l + 1)
                    [n.child_first as usize..(n.child_first + n.child_count) as usize]
                    .iter()
                    .map(|c| c.radius)
                    .fold(0.0, f32::max)
            } else {
                1.28f32.min(1.44)
            };
            assert!(
                n.radius >= largest_child * 0.999,
                "node {id}: radius {} < child {largest_child}",
                n.radius
            );
            // Bounds contain the children's bounds.
            if l + 1 < last {
                for c in &f.level_nodes(l + 1)
                    [n.child_first as usize..(n.child_first + n.child_count) as usize]
                {
                    for k in 0..3 {
                        assert!(
                            c.bounds_min[k] >= n.bounds_min[k]
                                && c.bounds_max[k] <= n.bounds_max[k]
                        );
                    }
                }
            }
            // A chunk's root holds up to the root points; every other node a cluster.
            let max_children = if l == 0 || chunked {
                params.max_root_points
            } else {
                params.max_cluster_size
            };
            assert!(n.child_count <= max_children);
            assert_eq!(nodes[id].level as usize, l);
        }
    }
    // Area of the top equals all particles' area.
    let total: f64 = frame
        .species_index
        .iter()
        .map(|&s| if s == 0 { 1.28f64 * 1.28 } else { 1.44 * 1.44 })
        .sum();
    assert!((f64::from(nodes[0].area_sum) - total).abs() / total < 1e-5);
    assert!(levels[1].point_count <= u64::from(params.max_root_points));

    // Attribute survives within its quantization step.
    assert_eq!(info.name, "c_pe");
    let a = f.attribute().unwrap();
    let step = (info.max - info.min) / 65535.0;
    let mut dec: Vec<f32> = a.iter().map(|&q| info.decode(q)).collect();
    let mut inp: Vec<f32> = frame.attribute.as_ref().unwrap().values.clone();
    dec.sort_by(f32::total_cmp);
    inp.sort_by(f32::total_cmp);
    for (d, i) in dec.iter().zip(&inp) {
        assert!((d - i).abs() <= step, "attribute {d} vs {i}");
    }
}

#[test]
fn round_trip_u16_delta1() {
    check_round_trip(
        &test_frame(16),
        BuildParams {
            max_root_points: 64,
            ..Default::default()
        },
    );
}

#[test]
fn round_trip_u8_delta2() {
    check_round_trip(
        &test_frame(12),
        BuildParams {
            max_root_points: 32,
            delta_n: 2,
            position_bits: 8,
            max_cluster_size: 6,
        },
    );
}

#[test]
fn chunked_round_trip_u16_delta1() {
    // About 8700 particles in chunks of at most 1000: the lattice, the duplicates and
    // the sparse cloud land in chunks of different depths.
    check_round_trip_with(
        &test_frame(16),
        &chunked(
            BuildParams {
                max_root_points: 64,
                ..Default::default()
            },
            1000,
            1 << 30,
        ),
    );
}

#[test]
fn chunked_round_trip_u8_delta3() {
    check_round_trip_with(
        &test_frame(12),
        &chunked(
            BuildParams {
                max_root_points: 32,
                delta_n: 3,
                position_bits: 8,
                max_cluster_size: 6,
            },
            400,
            1 << 30,
        ),
    );
}

#[test]
fn chunked_round_trip_with_a_finer_first_grid() {
    // About 16 500 particles in chunks of at most 200: more than 64 chunks' worth, so the
    // first partition grid is 16×16×16 rather than 8×8×8; the file still does not depend
    // on the thread count.
    let frame = test_frame(20);
    let opts = chunked(
        BuildParams {
            max_root_points: 200,
            ..Default::default()
        },
        200,
        1 << 30,
    );
    check_round_trip_with(&frame, &opts);
    assert_eq!(converted(&frame, &opts, 1), converted(&frame, &opts, 3));
}

/// The bytes of `frame` converted with `opts` on `threads` threads.
fn converted(frame: &Frame, opts: &ConvertOptions, threads: usize) -> Vec<u8> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.mdlod");
    pool.install(|| convert_frame(frame, None, &path, opts, &NoProgress).unwrap());
    std::fs::read(&path).unwrap()
}

#[test]
fn chunked_round_trip_of_coincident_points() {
    // 3000 copies of one point exceed a chunk: they are split by order.
    let mut frame = test_frame(6);
    for _ in 0..3000 {
        frame.positions.push([5.0, 5.0, 5.0]);
        frame.species_index.push(1);
        frame.attribute.as_mut().unwrap().values.push(1.0);
    }
    check_round_trip_with(
        &frame,
        &chunked(
            BuildParams {
                max_root_points: 64,
                delta_n: 2,
                ..Default::default()
            },
            500,
            1 << 30,
        ),
    );
}

#[test]
fn chunked_output_is_identical_whatever_the_memory_limit_and_threads() {
    let frame = test_frame(16);
    let params = BuildParams {
        max_root_points: 64,
        ..Default::default()
    };
    let bytes = |threads: usize, limit: u64| {
        converted(&frame, &chunked(params.clone(), 1000, limit), threads)
    };
    // One chunk at a time, then several.
    let one_at_a_time = mdlod_preprocess::chunked::chunk_memory(1000);
    let a = bytes(1, one_at_a_time);
    assert_eq!(a, bytes(3, 1 << 32));
    assert_eq!(a, bytes(2, one_at_a_time));
}

#[test]
fn chunked_conversion_refuses_a_limit_below_one_chunk() {
    let frame = test_frame(8);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.mdlod");
    let opts = chunked(
        BuildParams {
            max_root_points: 64,
            ..Default::default()
        },
        500,
        1 << 20,
    );
    let err = convert_frame(&frame, None, &path, &opts, &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(err.contains("memory limit of 1 MiB"), "{err}");
    assert!(!path.exists());
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        0,
        "working files left"
    );
}

/// A source that counts the windows read from it.
struct Counted<'a> {
    inner: mdlod_preprocess::chunked::FrameSource<'a>,
    windows: std::sync::atomic::AtomicUsize,
}

impl mdlod_preprocess::chunked::ParticleSource for Counted<'_> {
    fn len(&self) -> usize {
        self.inner.len()
    }
    fn simulation_box(&self) -> Option<&mdlod_format::meta::SimulationBox> {
        self.inner.simulation_box()
    }
    fn windows(
        &self,
        window: usize,
        f: &mut mdlod_preprocess::chunked::WindowFn<'_>,
    ) -> Result<(), mdlod_preprocess::convert::ConvertError> {
        self.inner.windows(window, &mut |start, frame| {
            self.windows
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            f(start, frame)
        })
    }
}

#[test]
fn chunked_conversion_checks_its_options_before_reading_the_particles() {
    let frame = test_frame(8);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.mdlod");
    let metadata =
        mdlod_preprocess::convert::base_metadata(&frame, None, &ConvertOptions::default());
    let bad = [
        (
            BuildParams {
                max_cluster_size: 1,
                max_root_points: 64,
                ..Default::default()
            },
            1 << 30,
            "max cluster size 1",
        ),
        (
            BuildParams {
                max_root_points: 64,
                delta_n: 0,
                ..Default::default()
            },
            1 << 30,
            "delta_n 0",
        ),
        (
            BuildParams {
                max_root_points: 64,
                ..Default::default()
            },
            1024,
            "memory limit of 1024 bytes",
        ),
    ];
    for (params, limit, message) in bad {
        let source = Counted {
            inner: mdlod_preprocess::chunked::FrameSource(&frame, &[]),
            windows: 0.into(),
        };
        let err = mdlod_preprocess::chunked::convert_chunked(
            &source,
            metadata.clone(),
            &path,
            &chunked(params, 500, limit),
            &NoProgress,
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains(message), "{err}");
        assert_eq!(
            source.windows.into_inner(),
            0,
            "{message}: particles were read"
        );
        assert!(!path.exists());
    }
}

#[test]
fn single_particle_and_tiny_inputs() {
    for n in [1usize, 2, 3, 9] {
        let frame = Frame {
            positions: (0..n).map(|i| [i as f32, 0.0, 0.0]).collect(),
            species_index: vec![0; n],
            species: vec![SpeciesName {
                name: "Cu".into(),
                numeric_type: false,
                radius: None,
                ..Default::default()
            }],
            ..Default::default()
        };
        let (_d, f) = convert(&frame, BuildParams::default());
        f.verify().unwrap();
        assert_eq!(f.level_count(), 2);
        assert_eq!(f.decode_level(1).unwrap().len(), n);
    }
}

#[test]
fn output_is_byte_identical_whatever_the_thread_count() {
    let frame = test_frame(24);
    let bytes = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.mdlod");
        let opts = ConvertOptions {
            build: BuildParams {
                max_root_points: 100,
                ..Default::default()
            },
            radii: vec![],
            ..Default::default()
        };
        pool.install(|| convert_frame(&frame, None, &path, &opts, &NoProgress).unwrap());
        std::fs::read(&path).unwrap()
    };
    let one = bytes(1);
    assert_eq!(one, bytes(2));
    assert_eq!(one, bytes(5));
}

#[test]
fn non_finite_positions_are_refused() {
    let mut frame = test_frame(4);
    frame.positions[7] = [f32::NAN, 0.0, 0.0];
    let dir = tempfile::tempdir().unwrap();
    let err = convert_frame(
        &frame,
        None,
        &dir.path().join("x.mdlod"),
        &ConvertOptions::default(),
        &NoProgress,
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("particle 7") && err.contains("non-finite"),
        "{err}"
    );
    assert!(!dir.path().join("x.mdlod").exists());
}

#[test]
fn values_that_overflow_or_are_not_finite_are_refused_not_written() {
    let frame = test_frame(6);
    let n = frame.len();
    let chunks = chunked(
        BuildParams {
            max_root_points: 64,
            ..Default::default()
        },
        300,
        1 << 30,
    );
    for opts in [ConvertOptions::default(), chunks] {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.mdlod");
        // A finite coordinate whose distance to the others overflows single precision.
        let mut far = frame.clone();
        far.positions[n - 1] = [0.0, 3e38, 0.0];
        let e = convert_frame(&far, None, &path, &opts, &NoProgress)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(&format!("particle {} at", n - 1)) && e.contains("lies beyond ±1e37"),
            "{e}"
        );
        // An attribute value that is not finite (the readers refuse them; the library
        // takes frames from any caller).
        let mut nan = frame.clone();
        nan.attribute.as_mut().unwrap().values[n - 2] = f32::NAN;
        let e = convert_frame(&nan, None, &path, &opts, &NoProgress)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(&format!(
                "particle {} has a non-finite attribute value NaN",
                n - 2
            )),
            "{e}"
        );
        // A radius whose squares overflow summed over the frame, though not over one
        // chunk of 300 (the top node sums them all).
        let r = (1e38 / (n as f64 * 0.6)).sqrt() as f32;
        let mut big = opts.clone();
        big.radii = vec![("Cu".into(), r)];
        let e = convert_frame(&frame, None, &path, &big, &NoProgress)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("species `Cu`") && e.contains("squared radii of 1.67e38"),
            "{e}"
        );
        assert!(!path.exists());
        // Just inside both bounds, the file is written and reads back whole.
        far.positions[n - 1] = [0.0, 9e36, 0.0];
        big.radii = vec![("Cu".into(), r / 2.0)];
        convert_frame(&far, None, &path, &big, &NoProgress).unwrap();
        let f = MdlodFile::open(&path).unwrap();
        f.verify().unwrap();
        assert_eq!(f.particle_count() as usize, n);
    }
}

#[test]
fn a_delta_n_deeper_than_the_hierarchy_is_recorded_as_the_delta_n_in_effect() {
    // δn 8 over hierarchies of fewer levels: in memory (a frame under the root points:
    // two levels) and in chunks. Every point level and encoding ancestor clamps to the
    // hierarchy, so the file is that of δn = L − 1 and must say so to be readable.
    let mut small = test_frame(2);
    small.positions.truncate(20);
    small.species_index.truncate(20);
    small.attribute.as_mut().unwrap().values.truncate(20);
    let deep = BuildParams {
        delta_n: 8,
        max_root_points: 64,
        ..Default::default()
    };
    for (frame, opts) in [
        (
            small,
            ConvertOptions {
                build: deep.clone(),
                ..Default::default()
            },
        ),
        (test_frame(6), chunked(deep, 300, 1 << 30)),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.mdlod");
        let report = convert_frame(&frame, None, &path, &opts, &NoProgress).unwrap();
        let f = MdlodFile::open(&path).unwrap();
        f.verify().unwrap();
        let last = f.level_count() as u32 - 1;
        assert!(last < 8, "{last} levels below the top");
        assert_eq!(f.metadata().build.delta_n, last);
        assert_eq!(f.particle_count() as usize, frame.len());
        // The user is told that the δn asked for is not the one in effect.
        let said: Vec<_> = report
            .notes
            .iter()
            .filter(|n| n.starts_with("--delta-n 8:"))
            .collect();
        assert_eq!(said.len(), 1, "{:?}", report.notes);
        assert!(
            said[0].ends_with(&format!("records --delta-n {last}")),
            "{}",
            said[0]
        );
        // One that fits is not remarked on.
        let fits = ConvertOptions {
            build: BuildParams {
                delta_n: last,
                ..opts.build.clone()
            },
            ..opts
        };
        let report = convert_frame(&frame, None, &path, &fits, &NoProgress).unwrap();
        assert!(
            report.notes.iter().all(|n| !n.contains("--delta-n")),
            "{:?}",
            report.notes
        );
    }
}

#[test]
fn more_species_than_a_file_holds_are_refused() {
    // 65536 species (every u16 index in use; the format allows 1 to 65535), in memory and
    // in chunks: refused before anything is written.
    let n = 65536;
    let frame = Frame {
        positions: (0..n)
            .map(|i| [(i % 41) as f32, ((i / 41) % 41) as f32, (i / 1681) as f32].map(|v| v * 2.0))
            .collect(),
        species_index: (0..n).map(|i| i as u16).collect(),
        species: (0..n)
            .map(|i| SpeciesName {
                name: i.to_string(),
                numeric_type: true,
                radius: None,
                ..Default::default()
            })
            .collect(),
        ..Default::default()
    };
    let chunks = chunked(BuildParams::default(), 1 << 15, 1 << 30);
    for opts in [ConvertOptions::default(), chunks] {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.mdlod");
        let e = convert_frame(&frame, None, &path, &opts, &NoProgress)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("65536 species: a file holds at most 65535"),
            "{e}"
        );
        assert!(!path.exists());
    }
}

/// Further attributes (format 1.2's ATTRIBUTES and NODE_ATTRIBUTES): a copy of the first
/// kept as a second has its quantized values and, selected, node means equal to the
/// first's (means to rounding: the first's are made level by level, the second's from
/// the particles at once); a column of its own is quantized over its own range; the
/// selected file colours and hides by it; radii of their own weigh the means as they
/// weigh the first's. (Frames built in chunks: tests/chunked.rs.)
#[test]
fn further_attributes_round_trip_and_select_like_the_first() {
    for (params, sized) in [
        (BuildParams::default(), false),
        (
            BuildParams {
                delta_n: 2,
                max_root_points: 16,
                ..Default::default()
            },
            true,
        ),
    ] {
        let mut frame = test_frame(8);
        if sized {
            // Radii of their own, spanning a factor 4: area weights differ per particle.
            frame.radii = Some(
                (0..frame.len())
                    .map(|i| 0.5 + (i % 7) as f32 * 0.25)
                    .collect(),
            );
            frame.species[0].radius_range = Some((0.5, 2.0));
            frame.species[1].radius_range = Some((0.5, 2.0));
        }
        let first = frame.attribute.clone().unwrap();
        let own: Vec<f32> = frame.positions.iter().map(|p| p[0] - p[1]).collect();
        let further = [
            Attribute {
                name: "copy".into(),
                values: first.values.clone(),
            },
            Attribute {
                name: "x_minus_y".into(),
                values: own.clone(),
            },
        ];
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.mdlod");
        let opts = ConvertOptions {
            build: params.clone(),
            ..Default::default()
        };
        mdlod_preprocess::convert::convert_frame_with(
            &frame,
            &further,
            None,
            &path,
            &opts,
            &NoProgress,
        )
        .unwrap();
        let f = MdlodFile::open(&path).unwrap();
        f.verify().unwrap();
        assert_eq!(f.header().version_minor, 2);
        assert_eq!(f.attribute_names(), ["c_pe", "copy", "x_minus_y"]);
        let base_values = f.attribute().unwrap().to_vec();
        let base_nodes = f.nodes().to_vec();
        let copy = MdlodFile::open(&path)
            .unwrap()
            .select_attribute("copy")
            .unwrap();
        assert_eq!(copy.attribute().unwrap(), &base_values[..]);
        assert_eq!(copy.metadata().attribute.as_ref().unwrap().name, "copy");
        for (i, (a, b)) in base_nodes.iter().zip(copy.nodes()).enumerate() {
            let tol = 1e-5 * (1.0 + a.attribute.abs());
            assert!(
                (a.attribute - b.attribute).abs() <= tol,
                "node {i}: {} against {}",
                a.attribute,
                b.attribute
            );
            // Everything but the attribute is the file's own.
            assert_eq!(
                (a.centroid, a.area_sum, a.colour),
                (b.centroid, b.area_sum, b.colour)
            );
        }
        // The own column: its range, the top node's mean (every particle's, by area),
        // and its values, sorted, each within half a step of one of the input's.
        let other = MdlodFile::open(&path)
            .unwrap()
            .select_attribute("x_minus_y")
            .unwrap();
        let info = other.metadata().attribute.clone().unwrap();
        let (lo, hi) = own
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), &v| {
                (l.min(v), h.max(v))
            });
        assert_eq!((info.min, info.max), (lo, hi));
        let species = &f.metadata().species;
        let radius = |i: usize| -> f64 {
            let r = match &frame.radii {
                Some(r) => f64::from(r[i]),
                None => f64::from(species[usize::from(frame.species_index[i])].radius),
            };
            r * r
        };
        let (w, a): (f64, f64) = (0..frame.len())
            .map(|i| (radius(i) * f64::from(own[i]), radius(i)))
            .fold((0.0, 0.0), |(x, y), (p, q)| (x + p, y + q));
        let top = f64::from(other.nodes()[0].attribute);
        // (Stored radii are quantized: a relative step of 1.5e-5 in the weights.)
        assert!(
            (top - w / a).abs() <= 1e-3 * (1.0 + (w / a).abs()),
            "{top} against {}",
            w / a
        );
        let mut sorted: Vec<f32> = other
            .attribute()
            .unwrap()
            .iter()
            .map(|&q| info.decode(q))
            .collect();
        let mut want = own.clone();
        sorted.sort_by(f32::total_cmp);
        want.sort_by(f32::total_cmp);
        let step = (hi - lo) / 65535.0;
        for (d, v) in sorted.iter().zip(&want) {
            assert!((d - v).abs() <= 0.5 * step + 1e-4, "{d} against {v}");
        }
    }
    // Small values beside very large ones: each node's mean from its own particles,
    // within the values' range (sums of a whole level's run left small means anywhere
    // in ±10 beside a total of 10^17).
    let frame = test_frame(8);
    let split: Vec<f32> = frame
        .positions
        .iter()
        .map(|p| if p[2] < 40.0 { 1e12 } else { 1.0 })
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("split.mdlod");
    let report = mdlod_preprocess::convert::convert_frame_with(
        &frame,
        &[Attribute {
            name: "split".into(),
            values: split,
        }],
        None,
        &path,
        &ConvertOptions {
            build: BuildParams {
                max_root_points: 16,
                ..Default::default()
            },
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
    // Twelve decades kept linearly: said, with the remedy a further column has.
    assert!(
        report
            .notes
            .iter()
            .any(|n| n.contains("attribute split spans 12.0 decades")
                && n.contains("--attribute-log10=split keeps its logarithm")),
        "{:?}",
        report.notes
    );
    let f = MdlodFile::open(&path).unwrap();
    let means = f.extra_node_means(0).unwrap();
    assert!(
        means.iter().all(|&m| (1.0..=1e12).contains(&m)),
        "{means:?}"
    );
    assert!(
        means.contains(&1.0) && means.contains(&1e12),
        "{:?}",
        &means[..means.len().min(40)]
    );
    // Named as the first, or without a first: refused.
    let mut plain = test_frame(4);
    let again = Attribute {
        name: "c_pe".into(),
        values: plain.attribute.clone().unwrap().values,
    };
    let out = dir.path().join("d.mdlod");
    let e = mdlod_preprocess::convert::convert_frame_with(
        &plain,
        std::slice::from_ref(&again),
        None,
        &out,
        &ConvertOptions::default(),
        &NoProgress,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("attribute c_pe is given twice"), "{e}");
    plain.attribute = None;
    let e = mdlod_preprocess::convert::convert_frame_with(
        &plain,
        &[again],
        None,
        &out,
        &ConvertOptions::default(),
        &NoProgress,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("further attributes need a first"), "{e}");
}
