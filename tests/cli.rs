//! End-to-end tests of the `mdlod` program on real LAMMPS output and generated data.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use mdlod_datasets::{lammps_sample_path, LAMMPS_SAMPLES};
use mdlod_format::MdlodFile;
use mdlod_preprocess::readers::{DumpFile, ReadOptions};
use mdlod_preprocess::NoProgress;

fn mdlod(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mdlod"))
        .args(args)
        .output()
        .expect("the mdlod binary runs")
}

fn ok(args: &[&str]) -> String {
    let out = mdlod(args);
    assert!(
        out.status.success(),
        "mdlod {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

fn fails(args: &[&str]) -> String {
    let out = mdlod(args);
    assert!(!out.status.success(), "mdlod {args:?} should fail");
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(!err.contains("panicked"), "mdlod {args:?} panicked: {err}");
    err
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `mdlod generate ARGS -o OUT`, which must succeed; its standard output.
fn generate(args: &[&str], out: &Path) -> String {
    let mut all = vec!["generate"];
    all.extend(args);
    all.extend(["-o", s(out)]);
    ok(&all)
}

/// The nearest input particle of every decoded particle, through a hash grid.
fn max_nearest_distance(inputs: &[[f32; 3]], decoded: &[[f32; 3]], cell: f32) -> f64 {
    let key = |p: &[f32; 3]| p.map(|v| (v / cell).floor() as i64);
    let mut grid = std::collections::HashMap::<[i64; 3], Vec<[f32; 3]>>::new();
    for p in inputs {
        grid.entry(key(p)).or_default().push(*p);
    }
    let mut worst = 0.0f64;
    for d in decoded {
        let k = key(d);
        let mut best = f64::INFINITY;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    for p in grid
                        .get(&[k[0] + dx, k[1] + dy, k[2] + dz])
                        .into_iter()
                        .flatten()
                    {
                        let e: f64 = (0..3)
                            .map(|i| (f64::from(p[i]) - f64::from(d[i])).powi(2))
                            .sum();
                        best = best.min(e.sqrt());
                    }
                }
            }
        }
        worst = worst.max(best);
    }
    worst
}

#[test]
fn every_real_lammps_sample_round_trips_within_the_recorded_bound() {
    let dir = tempfile::tempdir().unwrap();
    for sample in LAMMPS_SAMPLES {
        let input = lammps_sample_path(sample.file);
        let out = dir.path().join(format!("{}.mdlod", sample.file));
        for precision in ["u16", "u8"] {
            ok(&[
                "convert",
                s(&input),
                "-o",
                s(&out),
                "--precision",
                precision,
            ]);
            let f = MdlodFile::open(&out).unwrap();
            f.verify().unwrap();
            // The last frame, as the reader sees it.
            let dump = DumpFile::open(&input).unwrap();
            let frame = dump
                .read_frame(dump.frame_count() - 1, &ReadOptions::default(), &NoProgress)
                .unwrap();
            assert_eq!(f.particle_count(), sample.atoms, "{}", sample.file);
            assert_eq!(f.metadata().timestep, sample.timesteps.last().copied());
            let names: Vec<&str> = f
                .metadata()
                .species
                .iter()
                .map(|s| s.name.as_str())
                .collect();
            let input_names: Vec<&str> = frame.species.iter().map(|s| s.name.as_str()).collect();
            assert_eq!(names, input_names);
            let mut counts = vec![0usize; names.len()];
            for &sp in f.species() {
                counts[sp as usize] += 1;
            }
            let mut input_counts = vec![0usize; names.len()];
            for &sp in &frame.species_index {
                input_counts[sp as usize] += 1;
            }
            assert_eq!(counts, input_counts, "{}", sample.file);
            let decoded = f.decode_level(f.level_count() - 1).unwrap();
            let bound = f.metadata().max_position_error;
            let worst = max_nearest_distance(&frame.positions, &decoded, 1.0);
            assert!(
                worst <= bound + 1e-9,
                "{} ({precision}): a particle decodes {worst} from the nearest input, bound {bound}",
                sample.file
            );
            // The bound is that of the quantization: under a step of the box.
            let limit = if precision == "u16" { 1e-3 } else { 0.5 };
            assert!(
                bound < limit,
                "{} ({precision}): bound {bound}",
                sample.file
            );
        }
    }
}

#[test]
fn info_json_has_the_promised_fields() {
    let dir = tempfile::tempdir().unwrap();
    let input = lammps_sample_path("cuag_alloy.unwrapped.dump");
    let out = dir.path().join("a.mdlod");
    let text = ok(&[
        "convert",
        s(&input),
        "-o",
        s(&out),
        "--frame",
        "2",
        "--attribute",
        "c_pe",
        "--radius",
        "Cu=1.3",
    ]);
    assert!(text.contains("max position error"), "{text}");
    let line = ok(&["info", s(&out), "--json"]);
    // One line, as every command's `--json` result.
    assert_eq!(line.trim_end().lines().count(), 1, "{line}");
    let json: serde_json::Value = serde_json::from_str(&line).unwrap();
    assert_eq!(json["ok"], true);
    for key in [
        "particles",
        "levels",
        "nodes",
        "species",
        "box",
        "timestep",
        "max_position_error",
    ] {
        assert!(!json[key].is_null(), "info --json lacks {key}: {json}");
    }
    assert_eq!(json["particles"], 864);
    assert_eq!(json["flat_axis"], serde_json::Value::Null);
    assert_eq!(json["source"]["frame"], 2);
    assert_eq!(json["attribute"]["name"], "c_pe");
    let species = json["species"].as_array().unwrap();
    let cu = species.iter().find(|s| s["name"] == "Cu").unwrap();
    assert!((cu["radius"].as_f64().unwrap() - 1.3).abs() < 1e-6);
    let ag = species.iter().find(|s| s["name"] == "Ag").unwrap();
    assert!(
        (ag["radius"].as_f64().unwrap() - 1.44).abs() < 1e-6,
        "standard radius of Ag"
    );
    let text = ok(&["info", s(&out)]);
    assert!(text.contains("particles    864"), "{text}");
    // The dump's `pp pp pp`, as text too.
    assert!(text.contains(", periodic along a, b, c\n"), "{text}");
    let slab = dir.path().join("slab.mdlod");
    let shrink = lammps_sample_path("cu_slab.shrinkwrap.dump");
    ok(&["convert", s(&shrink), "-o", s(&slab), "--last"]);
    let text = ok(&["info", s(&slab)]);
    assert!(text.contains(", periodic along a, b\n"), "{text}");
    // A two-dimensional box (GSD's Lz = 0): c wraps nothing, and is said to be flat.
    let flat = dir.path().join("flat.xyz");
    std::fs::write(
        &flat,
        "2\nLattice=\"10 0 0 0 10 0 0 0 0\" pbc=\"T T T\" Properties=species:S:1:pos:R:3\n\
         Ar 1 1 0\nAr 2 2 0\n",
    )
    .unwrap();
    let flat_out = dir.path().join("flat.mdlod");
    ok(&["convert", s(&flat), "-o", s(&flat_out)]);
    let text = ok(&["info", s(&flat_out)]);
    assert!(
        text.contains(", periodic along a, b; c has length 0 (a two-dimensional box)\n"),
        "{text}"
    );
    let text = ok(&["verify", s(&out)]);
    assert!(text.contains(": ok:"), "{text}");
    // One number, one form: a batch's ranges and a file's further attributes are written
    // as the file's own attribute is (the f32's shortest form), so `==` holds in a script.
    let d = dir.path().join("b.d");
    ok(&[
        "batch",
        s(&input),
        "-o",
        s(&d),
        "--attribute",
        "c_pe",
        "--attribute",
        "xu",
    ]);
    let batch: serde_json::Value = serde_json::from_str(&ok(&["info", s(&d), "--json"])).unwrap();
    let frames = std::fs::read_dir(&d)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "mdlod"))
        .collect::<Vec<_>>();
    let mut lowest = f64::INFINITY;
    for f in &frames {
        let one: serde_json::Value = serde_json::from_str(&ok(&["info", s(f), "--json"])).unwrap();
        let extra = &one["attributes"][0]["min"];
        let shortest: f64 = format!("{}", extra.as_f64().unwrap() as f32)
            .parse()
            .unwrap();
        assert_eq!(extra.as_f64().unwrap(), shortest, "{extra}");
        lowest = lowest.min(one["attribute"]["min"].as_f64().unwrap());
    }
    assert_eq!(batch["attribute"]["min"].as_f64().unwrap(), lowest);
    let text = ok(&["info", s(&d)]);
    assert!(text.contains("] over every frame"), "{text}");
    // A frame gone: the ranges are over the frames read, and say so, and the command
    // fails (`ok` false in JSON, with the description).
    std::fs::remove_file(&frames[0]).unwrap();
    let out = mdlod(&["info", s(&d)]);
    assert_eq!(out.status.code(), Some(1));
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("1 listed frame could not be read") && err.contains("mdlod verify"),
        "{err}"
    );
    let out = mdlod(&["info", s(&d), "--json"]);
    assert_eq!(out.status.code(), Some(1));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["ok"], false);
    assert_eq!(json["unreadable"].as_array().unwrap().len(), 1);
    assert!(json["error"]
        .as_str()
        .unwrap()
        .contains("could not be read"));
    let read = format!(
        "] over the {} frames read (not the 1 unreadable)",
        frames.len() - 1
    );
    assert!(
        text.contains("attribute    c_pe in [") && text.contains(&read),
        "{text}"
    );
    assert!(!text.contains("over every frame"), "{text}");
    // A batch that lists no frame yet: no particle count or species to describe.
    let manifest = d.join("dataset.json");
    let mut m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&manifest).unwrap()).unwrap();
    m["frames"] = serde_json::json!([]);
    std::fs::write(&manifest, m.to_string()).unwrap();
    let text = ok(&["info", s(&d)]);
    assert!(
        text.contains("frames       0")
            && !text.contains("particles    0")
            && !text.contains("species      "),
        "{text}"
    );
}

#[test]
fn generated_data_converts_identically_with_any_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("alloy.lammpstrj");
    ok(&[
        "generate",
        "alloy",
        "--particles",
        "30000",
        "-o",
        s(&dump),
        "--frames",
        "2",
    ]);
    let a = dir.path().join("a.mdlod");
    let b = dir.path().join("b.mdlod");
    ok(&["convert", s(&dump), "-o", s(&a), "--threads", "1"]);
    ok(&["convert", s(&dump), "-o", s(&b), "--threads", "2"]);
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    let f = MdlodFile::open(&a).unwrap();
    assert_eq!(f.particle_count(), 30000);
    assert_eq!(f.metadata().timestep, Some(100));
    assert_eq!(f.metadata().species.len(), 2);
}

#[test]
fn bad_inputs_give_clear_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o.mdlod");
    let empty = dir.path().join("empty.lammpstrj");
    std::fs::write(&empty, "").unwrap();
    let err = fails(&["convert", s(&empty), "-o", s(&out)]);
    assert!(
        err.contains("empty.lammpstrj") && err.contains("empty"),
        "{err}"
    );

    let truncated = dir.path().join("cut.lammpstrj");
    let text = std::fs::read_to_string(lammps_sample_path("cu_melt.custom.dump")).unwrap();
    std::fs::write(&truncated, &text[..text.len() - 200]).unwrap();
    // (Without --last, the frame before the cut one converts: a run still writing.)
    let err = fails(&["convert", s(&truncated), "-o", s(&out), "--last"]);
    assert!(
        err.contains("cut.lammpstrj:") && err.contains("truncated"),
        "{err}"
    );

    let nan = dir.path().join("nan.lammpstrj");
    std::fs::write(
        &nan,
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n2\nITEM: BOX BOUNDS pp pp pp\n0 1\n0 1\n0 1\nITEM: ATOMS id type x y z\n1 1 0 0 0\n2 1 nan 0 0\n",
    )
    .unwrap();
    let err = fails(&["convert", s(&nan), "-o", s(&out)]);
    assert!(err.contains("nan.lammpstrj:11"), "{err}");

    let err = fails(&[
        "convert",
        s(&lammps_sample_path("cu_melt.custom.dump")),
        "-o",
        s(&out),
        "--frame",
        "99",
    ]);
    assert!(err.contains("frame 99"), "{err}");
    let err = fails(&[
        "convert",
        s(&lammps_sample_path("cu_melt.custom.dump")),
        "-o",
        s(&out),
        "--attribute",
        "nope",
    ]);
    assert!(err.contains("nope") && err.contains("c_pe"), "{err}");
    let err = fails(&["convert", s(&empty), "-o", s(&out), "--radius", "Cu"]);
    assert!(err.contains("NAME=RADIUS"), "{err}");
    assert!(!out.exists(), "no output after failures");

    let not_mdlod = dir.path().join("x.mdlod");
    std::fs::write(
        &not_mdlod,
        b"hello, this is not an mdlod file at all, just some text.......",
    )
    .unwrap();
    let err = fails(&["info", s(&not_mdlod)]);
    assert!(
        err.contains("x.mdlod") && err.contains("not an .mdlod file"),
        "{err}"
    );
    let err = fails(&["verify", s(&dir.path().join("missing.mdlod"))]);
    assert!(err.contains("missing.mdlod"), "{err}");

    // A directory where a file belongs, and an output in a directory that does not exist.
    let sub = dir.path().join("sub");
    std::fs::create_dir(&sub).unwrap();
    let err = fails(&["convert", s(&sub), "-o", s(&out)]);
    assert!(err.contains("sub: is a directory"), "{err}");
    let err = fails(&["info", s(&sub)]);
    assert!(
        err.contains("sub: a directory is described as the frames of a batch"),
        "{err}"
    );
    let sample = lammps_sample_path("cu_melt.custom.dump");
    let nowhere = dir.path().join("nowhere");
    let err = fails(&["convert", s(&sample), "-o", s(&nowhere.join("a.mdlod"))]);
    assert!(
        err.contains("a.mdlod: the directory") && err.contains("nowhere does not exist"),
        "{err}"
    );
    assert!(!nowhere.exists());
}

#[test]
fn demo_generates_converts_and_verifies() {
    let dir = tempfile::tempdir().unwrap();
    let d: PathBuf = dir.path().join("demo");
    let text = ok(&["demo", "--particles", "20000", "--dir", s(&d)]);
    assert!(text.contains("verified"), "{text}");
    assert!(text.contains("particles    20000"), "{text}");
    assert!(d.join("crater.mdlod").exists());
}

/// Decodes an RGBA8 PNG.
fn read_png(path: &Path) -> (u32, u32, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    buf.truncate(info.buffer_size());
    assert_eq!(info.color_type, png::ColorType::Rgba);
    (info.width, info.height, buf)
}

#[test]
fn render_writes_a_picture_and_views_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let input = lammps_sample_path("cuag_alloy.unwrapped.dump");
    let file = dir.path().join("a.mdlod");
    ok(&["convert", s(&input), "-o", s(&file)]);
    let a = dir.path().join("a.png");
    let view = dir.path().join("view.json");
    let text = ok(&[
        "render",
        s(&file),
        "-o",
        s(&a),
        "--width",
        "160",
        "--height",
        "120",
        "--azimuth",
        "-40",
        "--elevation",
        "30",
        "--spp",
        "2",
        "--background",
        "#000000",
        "--save-view",
        s(&view),
    ]);
    assert!(text.contains("864 particles"), "{text}");
    let (w, h, pixels) = read_png(&a);
    assert_eq!((w, h), (160, 120));
    let covered = pixels
        .chunks(4)
        .filter(|p| p[0] > 0 || p[1] > 0 || p[2] > 0)
        .count();
    let share = covered as f64 / f64::from(w * h);
    assert!(
        (0.05..0.95).contains(&share),
        "spheres cover {share} of the image"
    );

    // The saved view reproduces the image exactly; a streaming pool ample for the file
    // converges to the same pixels.
    let from_view = |png: &Path, extra: &[&str]| {
        let mut args = vec!["render", s(&file), "-o", s(png), "--view", s(&view)];
        args.extend(["--width", "160", "--height", "120", "--spp", "2"]);
        args.extend(["--background", "#000000"]);
        args.extend(extra);
        ok(&args)
    };
    let b = dir.path().join("b.png");
    from_view(&b, &[]);
    assert_eq!(read_png(&a).2, read_png(&b).2);
    let c = dir.path().join("c.png");
    let text = from_view(&c, &["--gpu-memory", "16M"]);
    assert!(text.contains("first image after"), "{text}");
    assert_eq!(read_png(&a).2, read_png(&c).2);
    // A pool too small for the coarsest level would draw one sphere for all: refused.
    let out = mdlod(&["render", s(&file), "-o", s(&c), "--gpu-memory", "1K"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("cannot hold the file's coarsest level"),
        "{err}"
    );

    // Angles given with --view replace the saved ones and keep its target and distance:
    // the image of a view file that names them with those angles. A fit at those angles
    // is another distance (the fit depends on the direction).
    let d = dir.path().join("d.png");
    from_view(&d, &["--azimuth", "50", "--elevation", "10"]);
    let mut turned: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&view).unwrap()).unwrap();
    turned["azimuth_deg"] = 50.0.into();
    turned["elevation_deg"] = 10.0.into();
    let turned_path = dir.path().join("turned.json");
    std::fs::write(&turned_path, turned.to_string()).unwrap();
    let e = dir.path().join("e.png");
    let mut args = vec!["render", s(&file), "-o", s(&e), "--view", s(&turned_path)];
    args.extend(["--width", "160", "--height", "120"]);
    args.extend(["--spp", "2", "--background", "#000000"]);
    ok(&args);
    assert_eq!(read_png(&d).2, read_png(&e).2);
    assert_ne!(read_png(&a).2, read_png(&d).2);
    let fitted = dir.path().join("fitted.png");
    let mut args = vec!["render", s(&file), "-o", s(&fitted), "--azimuth", "50"];
    args.extend(["--elevation", "10", "--width", "160", "--height", "120"]);
    args.extend(["--spp", "2", "--background", "#000000"]);
    ok(&args);
    assert_ne!(read_png(&d).2, read_png(&fitted).2);
    let err = fails(&[
        "render",
        s(&file),
        "-o",
        s(&d),
        "--view",
        s(&view),
        "--elevation",
        "100",
    ]);
    assert!(err.contains("elevation_deg 100"), "{err}");
    // A field this version does not read (a misspelt one) is named, not silently lost.
    let typo = dir.path().join("typo.json");
    std::fs::write(&typo, r#"{"version": 1, "azimuth": 90}"#).unwrap();
    let out = ok(&["render", s(&file), "-o", s(&d), "--view", s(&typo)]);
    assert!(
        out.contains("field \"azimuth\" is not one this mdlod reads"),
        "{out}"
    );
    // The view records the image it was saved from; drawn narrower, the render says the
    // sides may be cut, and at the same shape (any size) nothing.
    let saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&view).unwrap()).unwrap();
    assert_eq!(saved["image"], serde_json::json!([160, 120]));
    let narrow = ok(&[
        "render",
        s(&file),
        "-o",
        s(&d),
        "--view",
        s(&view),
        "--width",
        "60",
        "--height",
        "120",
    ]);
    assert!(
        narrow.contains(
            "the view was saved from a 160×120 image; drawn 60×120, the image is narrower: data \
             at the sides may be cut"
        ),
        "{narrow}"
    );
    // Without --width and --height, the view draws at the size it was saved from.
    let sized = dir.path().join("sized.png");
    ok(&["render", s(&file), "-o", s(&sized), "--view", s(&view)]);
    assert_eq!(read_png(&sized).0, 160);
    assert_eq!(read_png(&sized).1, 120);
    let wide = ok(&[
        "render",
        s(&file),
        "-o",
        s(&sized),
        "--view",
        s(&view),
        "--width",
        "320",
    ]);
    // One side given: the other keeps the saved shape, so nothing is cut.
    assert!(!wide.contains("saved from"), "{wide}");
    assert_eq!((read_png(&sized).0, read_png(&sized).1), (320, 240));
    let same = ok(&[
        "render",
        s(&file),
        "-o",
        s(&d),
        "--view",
        s(&view),
        "--width",
        "320",
        "--height",
        "240",
    ]);
    assert!(!same.contains("saved from"), "{same}");
    // Without a view, one side alone keeps the default 16:9 shape.
    ok(&["render", s(&file), "-o", s(&sized), "--width", "64"]);
    assert_eq!((read_png(&sized).0, read_png(&sized).1), (64, 36));
    ok(&["render", s(&file), "-o", s(&sized), "--height", "27"]);
    assert_eq!((read_png(&sized).0, read_png(&sized).1), (48, 27));
    // `sample` takes the saved size too (it sampled 1280×720 before: a .sndf 50 times
    // as large), and its shading draws that image.
    let sndf = dir.path().join("v.sndf");
    ok(&[
        "sample",
        s(&file),
        "-o",
        s(&sndf),
        "--view",
        s(&view),
        "--iterations",
        "1",
    ]);
    let lit = dir.path().join("lit.png");
    ok(&["shade", s(&sndf), "-o", s(&lit)]);
    assert_eq!((read_png(&lit).0, read_png(&lit).1), (160, 120));
}

/// The LAMMPS sample `name` converted to `dir/a.mdlod`.
fn converted(dir: &Path, name: &str) -> PathBuf {
    let file = dir.join("a.mdlod");
    ok(&["convert", s(&lammps_sample_path(name)), "-o", s(&file)]);
    file
}

#[test]
fn a_headless_render_prints_no_display_errors() {
    // A batch job without a desktop session: no XDG_RUNTIME_DIR. Mesa's device-selection
    // layer (installed with its Vulkan drivers) would make libwayland print two `error:`
    // lines about it before a render that succeeds.
    let dir = tempfile::tempdir().unwrap();
    let file = converted(dir.path(), "cu_melt.xyz");
    let png = dir.path().join("x.png");
    let out = Command::new(env!("CARGO_BIN_EXE_mdlod"))
        .args([
            "render",
            s(&file),
            "-o",
            s(&png),
            "--width",
            "32",
            "--height",
            "24",
        ])
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("NODEVICE_SELECT")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(png.exists());
    assert!(!err.contains("error"), "{err}");
}

#[test]
fn render_without_an_adapter_says_how_to_get_one() {
    let dir = tempfile::tempdir().unwrap();
    let file = converted(dir.path(), "cu_melt.xyz");
    let out = Command::new(env!("CARGO_BIN_EXE_mdlod"))
        .args(["render", s(&file), "-o", s(&dir.path().join("x.png"))])
        .env("WGPU_BACKEND", "dx12")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("mesa-vulkan-drivers")
            && err.contains("backends tried: dx12")
            && !err.contains("panicked"),
        "{err}"
    );
    assert!(!dir.path().join("x.png").exists());
    // A name wgpu does not know is said to be one.
    let out = Command::new(env!("CARGO_BIN_EXE_mdlod"))
        .args(["render", s(&file), "-o", s(&dir.path().join("x.png"))])
        .env("WGPU_BACKEND", "vulcan")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("WGPU_BACKEND=vulcan names no graphics backend"),
        "{err}"
    );
}

#[test]
fn binary_lammps_dumps_convert_like_their_text_twins() {
    let dir = tempfile::tempdir().unwrap();
    let (bin, text) = (dir.path().join("bin.mdlod"), dir.path().join("text.mdlod"));
    let out = ok(&[
        "convert",
        s(&lammps_sample_path("cu_melt.custom.bin")),
        "-o",
        s(&bin),
        "--attribute",
        "c_pe",
    ]);
    assert!(out.contains("500 particles"), "{out}");
    ok(&[
        "convert",
        s(&lammps_sample_path("cu_melt.custom.dump")),
        "-o",
        s(&text),
        "--attribute",
        "c_pe",
    ]);
    let (b, t) = (
        MdlodFile::open(&bin).unwrap(),
        MdlodFile::open(&text).unwrap(),
    );
    b.verify().unwrap();
    // The last frame of both is step 500 of the same run.
    assert_eq!(b.metadata().timestep, Some(500));
    assert_eq!(b.metadata().timestep, t.metadata().timestep);
    assert_eq!(b.metadata().time, t.metadata().time);
    assert_eq!(b.metadata().units.as_deref(), Some("metal"));
    assert_eq!(b.particle_count(), t.particle_count());
    // A column list for a dump that names its own is refused, naming the file and
    // what it names.
    let err = fails(&[
        "convert",
        s(&lammps_sample_path("cu_melt.atom.bin")),
        "-o",
        s(&bin),
        "--columns",
        "id type x y",
    ]);
    assert!(
        err.contains("cu_melt.atom.bin")
            && err.contains("this dump names its own columns (id type xs ys zs)"),
        "{err}"
    );
}

/// The invariants a batch directory keeps whenever a batch is killed: every visible
/// `.mdlod` is complete and equals the uninterrupted run's, and the manifest lists only
/// such files.
fn check_batch_dir(dir: &Path, reference: &mdlod_preprocess::batch::Manifest) {
    let expected = |ts: u64| {
        reference
            .frames
            .iter()
            .find(|f| f.timestep == ts)
            .map(|f| f.checksum.clone())
    };
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') || name == "dataset.json" {
            continue;
        }
        let ts: u64 = name
            .strip_prefix("frame-")
            .and_then(|n| n.strip_suffix(".mdlod"))
            .and_then(|n| n.parse().ok())
            .unwrap_or_else(|| panic!("unexpected file {name}"));
        let f = MdlodFile::open(e.path()).unwrap_or_else(|e| panic!("{name}: {e}"));
        f.verify().unwrap();
        assert_eq!(
            Some(format!("{:016x}", f.header().section_table_checksum)),
            expected(ts),
            "{name}"
        );
    }
    if dir.join("dataset.json").exists() {
        let m = mdlod_preprocess::batch::read_manifest(dir).unwrap();
        for f in &m.frames {
            assert!(
                dir.join(&f.file).is_file(),
                "manifest lists missing {}",
                f.file
            );
            assert_eq!(Some(f.checksum.clone()), expected(f.timestep));
        }
    }
}

#[test]
fn killing_a_batch_at_any_moment_leaves_only_complete_frames_and_a_true_manifest() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("alloy.lammpstrj");
    generate(&["alloy", "-n", "60000", "--frames", "6"], &input);
    let reference = dir.path().join("reference");
    ok(&["batch", s(&input), "-o", s(&reference), "--threads", "2"]);
    let reference = mdlod_preprocess::batch::read_manifest(&reference).unwrap();
    assert_eq!(reference.frames.len(), 6);

    let work = dir.path().join("work");
    // The uninterrupted run takes about 2 s here: the kills land while frames are being
    // read, built, written and renamed, and while the manifest is rewritten.
    let mut frames_seen = vec![];
    for (signal, delay_ms) in [
        ("KILL", 50),
        ("INT", 250),
        ("KILL", 400),
        ("INT", 500),
        ("TERM", 550),
        ("KILL", 600),
        ("INT", 700),
        ("INT", 900),
        ("INT", 1100),
    ] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_mdlod"))
            .args(["batch", s(&input), "-o", s(&work), "--threads", "2"])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(delay_ms));
        let status = Command::new("kill")
            .args([&format!("-{signal}"), &child.id().to_string()])
            .status()
            .unwrap();
        assert!(status.success() || child.try_wait().unwrap().is_some());
        let ended_pid = child.id();
        let ended = child.wait_with_output().unwrap();
        // An interrupt the handler caught says how to go on.
        if ended.status.code() == Some(130) {
            let err = String::from_utf8_lossy(&ended.stderr);
            assert!(
                err.contains("a rerun of the same command converts only the rest"),
                "{err}"
            );
            // The handler removed the frames being written, not only the working
            // directory (only a kill leaves a temporary frame for the next run).
            let pid = ended_pid;
            let partial: Vec<String> = std::fs::read_dir(&work)
                .unwrap()
                .flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.ends_with(".tmp") && n.contains(&format!("-{pid}-")))
                .collect();
            assert!(
                partial.is_empty(),
                "{signal} at {delay_ms} ms left {partial:?}"
            );
        }
        check_batch_dir(&work, &reference);
        frames_seen
            .push(mdlod_preprocess::batch::read_manifest(&work).map_or(0, |m| m.frames.len()));
    }
    // Some kills interrupted the work (not everything was done before the last one).
    assert!(frames_seen.iter().any(|&n| n < 6), "{frames_seen:?}");
    // A rerun finishes the job and agrees with the uninterrupted run.
    ok(&["batch", s(&input), "-o", s(&work), "--threads", "2"]);
    check_batch_dir(&work, &reference);
    let done = mdlod_preprocess::batch::read_manifest(&work).unwrap();
    assert_eq!(done.frames, reference.frames);
}

#[test]
fn batch_takes_its_shard_from_a_slurm_job_array() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("d");
    let input = lammps_sample_path("cu_melt.custom.dump");
    // --array=1-5:2: tasks 1, 3 and 5.
    for id in [1, 3, 5] {
        let run = Command::new(env!("CARGO_BIN_EXE_mdlod"))
            .args(["batch", s(&input), "-o", s(&out)])
            .env("SLURM_ARRAY_TASK_ID", id.to_string())
            .env("SLURM_ARRAY_TASK_MIN", "1")
            .env("SLURM_ARRAY_TASK_STEP", "2")
            .env("SLURM_ARRAY_TASK_COUNT", "3")
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&run.stdout);
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
        assert!(
            text.contains(&format!(
                "in shard {} of 3 (from the Slurm job array's variables: `mdlod batch --merge` \
                 joins the shards' manifests once every task has ended; --shard none converts \
                 every frame into dataset.json)",
                (id - 1) / 2
            )),
            "{text}"
        );
    }
    // Before the merge, a movie of the directory says to merge (not "no dataset.json").
    let png = dir.path().join("m").join("f-%03d.png");
    let err = fails(&["render", s(&out), "-o", s(&png)]);
    assert!(
        err.contains("have not been merged; run `mdlod batch --merge"),
        "{err}"
    );
    let merged = ok(&["batch", "--merge", s(&out)]);
    assert!(merged.contains("merged 6 frames"), "{merged}");
    // A whole run's directory: nothing to merge, which is no failure (a pipeline's merge
    // step after any batch).
    let whole = dir.path().join("whole");
    ok(&["batch", s(&input), "-o", s(&whole)]);
    let again = ok(&["batch", "--merge", s(&whole), "--json"]);
    let v: serde_json::Value = serde_json::from_str(&again).unwrap();
    assert!(
        v["ok"] == true && v["merged"] == 0 && v["frames"] == 6,
        "{again}"
    );
    let again = ok(&["batch", "--merge", s(&whole)]);
    assert!(
        again.contains("nothing to merge: no shard manifests beside")
            && again.contains("which lists 6 frames"),
        "{again}"
    );
    // A directory that is not there is named as such, with what --merge takes.
    let err = fails(&["batch", "--merge", s(&dir.path().join("elsewhere"))]);
    assert!(
        err.contains("elsewhere: no such directory") && err.contains("--shard I/N"),
        "{err}"
    );
    let err = fails(&["batch", s(&input), "-o", s(&out), "--shard", "3/3"]);
    assert!(err.contains("index 3 must be below the count 3"), "{err}");
    // A task id without the array's count converts nothing, naming what is missing.
    let run = Command::new(env!("CARGO_BIN_EXE_mdlod"))
        .args(["batch", s(&input), "-o", s(&dir.path().join("e"))])
        .env("SLURM_ARRAY_TASK_ID", "1")
        .env_remove("SLURM_ARRAY_TASK_COUNT")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(
        err.contains("SLURM_ARRAY_TASK_ID is set but not SLURM_ARRAY_TASK_COUNT"),
        "{err}"
    );
    // The batch directory it would have made is not left behind.
    assert!(!dir.path().join("e").exists());
}

/// The density volume and its iso-surface need no precomputation: they render every
/// frame of a batch directory as converted, directly or streamed through a small GPU
/// pool (the same pixels).
#[test]
fn density_and_iso_render_every_frame_of_a_batch_streamed_or_not() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("d");
    let input = lammps_sample_path("cu_melt.custom.dump");
    ok(&["batch", s(&input), "-o", s(&out), "--threads", "2"]);
    let mut frames: Vec<PathBuf> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "mdlod"))
        .collect();
    frames.sort();
    assert!(frames.len() >= 2, "{frames:?}");
    let mut pictures = vec![];
    for (k, frame) in frames.iter().enumerate() {
        for mode in ["density", "iso"] {
            let png = |tag: &str| dir.path().join(format!("{k}-{mode}-{tag}.png"));
            let mut args = vec!["render", s(frame), "--mode", mode, "--slices", "48"];
            args.extend(["--width", "96", "--height", "72", "--azimuth", "20"]);
            let direct = png("direct");
            let text = ok(&[args.as_slice(), &["-o", s(&direct)]].concat());
            assert!(text.contains("slice stacks run"), "{text}");
            let streamed = png("streamed");
            let text = ok(&[
                args.as_slice(),
                &["-o", s(&streamed), "--gpu-memory", "256K"],
            ]
            .concat());
            assert!(text.contains("first image after"), "{text}");
            let (a, b) = (read_png(&direct).2, read_png(&streamed).2);
            assert!(a == b, "frame {k}, {mode}: streaming changed the picture");
            pictures.push(a);
        }
    }
    // Each frame shows its own data.
    assert!(pictures[0] != pictures[2] && pictures[1] != pictures[3]);
}

/// Runs mdlod under a file-size limit (`ulimit -f`, with SIGXFSZ ignored, so writes past
/// it fail with EFBIG exactly as they would on a full disk with ENOSPC).
#[cfg(unix)]
fn mdlod_limited(blocks: u32, args: &[&str]) -> Output {
    mdlod_in_shell(&format!("ulimit -f {blocks}; trap '' XFSZ"), args)
}

/// Runs mdlod after the shell commands `setup` (resource limits).
#[cfg(unix)]
fn mdlod_in_shell(setup: &str, args: &[&str]) -> Output {
    let quoted: Vec<String> = args.iter().map(|a| format!("'{a}'")).collect();
    Command::new("sh")
        .arg("-c")
        .arg(format!(
            "{setup}; exec '{}' {}",
            env!("CARGO_BIN_EXE_mdlod"),
            quoted.join(" ")
        ))
        .output()
        .unwrap()
}

/// 40 000 particles in chunks of 500 are partitioned into 16×16×16 cells first, more
/// files than a limit of 64 open files (soft and hard) lets stay open: each cell's file
/// is then reopened for every append, and the file is the same byte for byte.
#[cfg(unix)]
#[test]
fn a_low_open_file_limit_gives_the_same_out_of_core_file() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.lammpstrj");
    ok(&["generate", "alloy", "-n", "40000", "-o", s(&input)]);
    let args = |out: &Path| {
        let out = out.to_str().unwrap().to_owned();
        let input = s(&input).to_owned();
        [
            "convert".to_owned(),
            input,
            "-o".into(),
            out,
            "--chunk-points".into(),
            "500".into(),
            "--root-points".into(),
            "500".into(),
        ]
    };
    let free = dir.path().join("free.mdlod");
    let a = args(&free);
    ok(&a.iter().map(String::as_str).collect::<Vec<_>>());
    let limited = dir.path().join("limited.mdlod");
    let a = args(&limited);
    let run = mdlod_in_shell(
        "ulimit -n 64",
        &a.iter().map(String::as_str).collect::<Vec<_>>(),
    );
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(std::fs::read(&free).unwrap() == std::fs::read(&limited).unwrap());
}

#[cfg(unix)]
#[test]
fn a_full_disk_gives_a_clear_error_and_no_partial_output() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.lammpstrj");
    generate(&["alloy", "-n", "40000", "--frames", "2"], &input);
    let out_dir = dir.path().join("out");
    std::fs::create_dir(&out_dir).unwrap();
    let out = out_dir.join("frame.mdlod");
    let run = mdlod_limited(100, &["convert", s(&input), "-o", s(&out)]);
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(
        err.contains(&format!("{}: File too large", out.display())),
        "{err}"
    );
    // Out of core, the first working files to outgrow the limit are the partition's
    // cells, written on their own thread: the error still names one.
    let chunked = [
        "convert",
        s(&input),
        "-o",
        s(&out),
        "--chunk-points",
        "10000",
    ];
    let run = mdlod_limited(2, &chunked);
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(
        err.contains("working file") && err.contains(".cell: File too large"),
        "{err}"
    );
    // Room for every cell but not the output, which goes through its own writing
    // thread with direct I/O: the error still names the output.
    let run = mdlod_limited(200, &chunked);
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(
        err.contains(&format!("{}: File too large", out.display())),
        "{err}"
    );
    let batch_dir = dir.path().join("batch");
    let run = mdlod_limited(100, &["batch", s(&input), "-o", s(&batch_dir)]);
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(
        err.contains(".mdlod: File too large") && err.contains("frame-"),
        "{err}"
    );
    // Nothing partial, visible or hidden (the batch's directory may be gone whole).
    for d in [&out_dir, &batch_dir] {
        let Ok(entries) = std::fs::read_dir(d) else {
            assert!(!d.exists());
            continue;
        };
        let names: Vec<String> = entries
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n != "dataset.json")
            .collect();
        assert!(names.is_empty(), "left behind: {names:?}");
    }
    // The batch wrote no frame, and had no manifest before: it leaves none.
    assert!(!batch_dir.join("dataset.json").exists());
}

/// S-NDFs of a perspective view are binned along each texel's ray (`.sndf` version 1.2,
/// `normal_frame`), which `info` says, and nothing is noted about wide views. A file an
/// earlier mdlod sampled in the camera's frame still shades, with a note at wide fields
/// of view from `shade` and `info`; at 30° nothing is said.
#[test]
fn perspective_sndfs_are_binned_along_rays_and_earlier_files_are_noted() {
    let dir = tempfile::tempdir().unwrap();
    let file = converted(dir.path(), "cu_melt.xyz");
    let wide = dir.path().join("wide.json");
    std::fs::write(&wide, r#"{"version": 1, "fov_y_deg": 70}"#).unwrap();
    let png = dir.path().join("w.png");
    let sndf = dir.path().join("w.sndf");
    let size = ["--width", "32", "--height", "24", "--iterations", "1"];
    let out = ok(&[
        &["render", s(&file), "-o", s(&png), "--mode", "sndf"][..],
        &size,
        &["--view", s(&wide)],
    ]
    .concat());
    assert!(!out.contains("note:"), "{out}");
    let out = ok(&[
        &["sample", s(&file), "-o", s(&sndf), "--view", s(&wide)][..],
        &size,
    ]
    .concat());
    assert!(!out.contains("note:"), "{out}");
    assert_eq!(&std::fs::read(&sndf).unwrap()[8..12], &[1, 0, 2, 0]);
    let out = ok(&["info", s(&sndf)]);
    assert!(out.contains("binned along each texel's ray"), "{out}");
    let out = ok(&["info", s(&sndf), "--json"]);
    assert!(out.contains(r#""normal_frame":"ray""#), "{out}");
    // As an earlier mdlod wrote it: no normal frame, version 1.0.
    let earlier = dir.path().join("earlier.sndf");
    let mut data = mdlod_format::sndf::SndfData::load(&sndf).unwrap();
    data.header.normal_frame = None;
    data.save(&earlier).unwrap();
    assert_eq!(&std::fs::read(&earlier).unwrap()[8..12], &[1, 0, 0, 0]);
    let note = "an earlier mdlod sampled these S-NDFs binning the normals in the camera's frame";
    let out = ok(&["shade", s(&earlier), "-o", s(&png)]);
    assert!(out.contains(note) && out.contains("70°"), "{out}");
    assert!(ok(&["info", s(&earlier)]).contains(note));
    let out = ok(&["info", s(&earlier), "--json"]);
    assert!(out.contains(r#""normal_frame":"camera""#), "{out}");
    data.header.view = serde_json::json!({"version": 1, "fov_y_deg": 30, "distance": 50});
    data.save(&earlier).unwrap();
    let out = ok(&["shade", s(&earlier), "-o", s(&png)]);
    assert!(!out.contains("note:"), "{out}");
    // A wide strip at 30°: its corners are 65° off the axis.
    let narrow = dir.path().join("narrow.json");
    std::fs::write(&narrow, r#"{"version": 1, "fov_y_deg": 30}"#).unwrap();
    ok(&[
        "sample",
        s(&file),
        "-o",
        s(&sndf),
        "--view",
        s(&narrow),
        "--width",
        "64",
        "--height",
        "8",
        "--iterations",
        "1",
    ]);
    let mut strip = mdlod_format::sndf::SndfData::load(&sndf).unwrap();
    strip.header.normal_frame = None;
    strip.save(&earlier).unwrap();
    let out = ok(&["shade", s(&earlier), "-o", s(&png)]);
    assert!(
        out.contains(note) && out.contains("(65° off the axis at the corners)"),
        "{out}"
    );
}

/// `sample --tiles` stores the S-MIP tiles of an orthographic view; `shade` lights them
/// into the picture `render --mode sndf` gives (sampled whole, one cut: equal up to the
/// rectangles' cut borders), and into a coarser level made from them. A perspective view
/// is refused.
#[test]
fn smip_tiles_sampled_once_shade_without_the_particles() {
    let dir = tempfile::tempdir().unwrap();
    let mdlod = dir.path().join("melt.mdlod");
    ok(&[
        "convert",
        s(&lammps_sample_path("cu_melt.custom.dump")),
        "-o",
        s(&mdlod),
    ]);
    let sndf = dir.path().join("tiles.sndf");
    let view = [
        "--width",
        "96",
        "--height",
        "64",
        "--ortho",
        "--zoom",
        "2",
        "--iterations",
        "8",
        "--bins",
        "4",
    ];
    let out = ok(&[&["sample", s(&mdlod), "-o", s(&sndf), "--tiles"][..], &view].concat());
    let mib = std::fs::metadata(&sndf).unwrap().len() as f64 / 1048576.0;
    assert!(
        out.contains(&format!("({mib:.1} MiB: ")) && out.contains("S-MIP tiles"),
        "{out}"
    );
    // `info` says which level of the tiles its view is shown at: level 0 for tiles
    // sampled at the view's pixels, level 3 for the same tiles' texels an eighth the
    // size (as --min-samples samples them), whatever the header's display bias.
    let text = ok(&["info", s(&sndf)]);
    assert!(
        text.contains("shown at     level 0 of its S-MIP tiles"),
        "{text}"
    );
    let finer = dir.path().join("finer.sndf");
    let mut data = mdlod_format::sndf::SndfData::load(&sndf).unwrap();
    data.header.smip.as_mut().unwrap().texel0 /= 8.0;
    data.save(&finer).unwrap();
    let text = ok(&["info", s(&finer)]);
    assert!(
        text.contains("shown at     level 3 of its S-MIP tiles"),
        "{text}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&ok(&["info", s(&finer), "--json"])).unwrap();
    assert_eq!(json["display_level"], 0);
    assert_eq!(
        json["shown_at_levels"],
        serde_json::json!([{"level": 3, "weight": 1.0}])
    );
    // A tile file's view without the distance that scales it is refused, not fitted
    // to a box of its own making.
    let unscaled = dir.path().join("unscaled.sndf");
    data.header.view.as_object_mut().unwrap().remove("distance");
    data.save(&unscaled).unwrap();
    let png = dir.path().join("unscaled.png");
    for args in [
        vec!["shade", s(&unscaled), "-o", s(&png)],
        vec!["info", s(&unscaled)],
    ] {
        let e = fails(&args);
        assert!(
            e.contains("unscaled.sndf") && e.contains("no `target` or no `distance`"),
            "{args:?}: {e}"
        );
    }
    assert!(!png.exists());
    let direct = dir.path().join("direct.png");
    ok(&[
        &["render", s(&mdlod), "-o", s(&direct), "--mode", "sndf"][..],
        &view,
    ]
    .concat());
    let other = dir.path().join("other.sndf");
    let perspective = fails(&[
        "sample",
        s(&mdlod),
        "-o",
        s(&other),
        "--tiles",
        "--width",
        "8",
        "--height",
        "8",
    ]);
    assert!(perspective.contains("orthographic"), "{perspective}");
    assert!(!other.exists());
    // --min-samples samples the tiles finer than the view's pixels, as it samples one
    // image, and the view's level is shaded from them: closer to many rays at the
    // image's size than the tiles sampled at it (it used to only relabel them).
    let small = ["--width", "48", "--height", "32", "--ortho", "--bins", "2"];
    let sampled = |name: &str, extra: &[&str]| {
        let path = dir.path().join(name);
        let out = ok(&[&["sample", s(&mdlod), "-o", s(&path)][..], &small, extra].concat());
        let png = path.with_extension("png");
        ok(&["shade", s(&path), "-o", s(&png)]);
        (out, read_png(&png).2, path)
    };
    let (_, reference, _) = sampled("ref.sndf", &["--iterations", "64"]);
    let (_, plain, _) = sampled("plain.sndf", &["--tiles", "--iterations", "4"]);
    let (out, fine, fine_file) = sampled(
        "fine.sndf",
        &["--tiles", "--iterations", "4", "--min-samples", "64"],
    );
    assert!(
        out.contains("sampled at") && out.contains("image size"),
        "{out}"
    );
    let text = ok(&["info", s(&fine_file)]);
    assert!(!text.contains("shown at     level 0 "), "{text}");
    let off = |img: &[u8]| {
        img.iter()
            .zip(&reference)
            .map(|(a, b)| f64::from(a.abs_diff(*b)))
            .sum::<f64>()
            / img.len() as f64
    };
    assert!(
        off(&fine) * 3.0 < off(&plain),
        "{} against {}",
        off(&fine),
        off(&plain)
    );
    std::fs::remove_file(&mdlod).unwrap();
    let shaded = dir.path().join("shaded.png");
    let out = ok(&["shade", s(&sndf), "-o", s(&shaded)]);
    assert!(out.contains("no particle data read"), "{out}");
    let (w, h, a) = read_png(&shaded);
    let (_, _, b) = read_png(&direct);
    assert_eq!((w, h), (96, 64));
    let differ = a
        .chunks(4)
        .zip(b.chunks(4))
        .filter(|(p, q)| p.iter().zip(*q).any(|(x, y)| x.abs_diff(*y) > 8))
        .count();
    assert!(differ * 50 <= 96 * 64, "{differ} pixels differ");
    let coarse = dir.path().join("coarse.png");
    ok(&["shade", s(&sndf), "-o", s(&coarse), "--level", "1"]);
    assert_eq!(read_png(&coarse).0, 48);
    // 96 texels halve to one at level 7: the one-texel image, and nothing past it.
    ok(&["shade", s(&sndf), "-o", s(&coarse), "--level", "7"]);
    assert_eq!(read_png(&coarse).0, 1);
    let e = fails(&["shade", s(&sndf), "-o", s(&coarse), "--level", "8"]);
    assert!(
        e.contains("96x64 texels halve to one at level 7 (levels 0 to 7)"),
        "{e}"
    );
}

#[test]
fn sndfs_sampled_once_shade_without_the_particles() {
    let dir = tempfile::tempdir().unwrap();
    let mdlod = dir.path().join("melt.mdlod");
    ok(&[
        "convert",
        s(&lammps_sample_path("cu_melt.custom.dump")),
        "-o",
        s(&mdlod),
    ]);
    let sndf = dir.path().join("view.sndf");
    let size = ["--width", "96", "--height", "64"];
    let sampled = ok(&[
        &[
            "sample",
            s(&mdlod),
            "-o",
            s(&sndf),
            "--iterations",
            "8",
            "--binning",
            "lambert",
        ][..],
        &size,
    ]
    .concat());
    assert!(sampled.contains("8 rays each"), "{sampled}");
    // The file's size is said: 96·64 texels of 8·8 bins of 16 bytes, and its header.
    let bytes = std::fs::metadata(&sndf).unwrap().len();
    assert!(bytes > 96 * 64 * 64 * 16, "{bytes}");
    let said = format!("({:.1} MiB: 96x64 texels", bytes as f64 / 1048576.0);
    assert!(sampled.contains(&said), "{said}: {sampled}");
    // A header whose camera shade could not use (forged: a field of view of 0) is
    // refused by shade and info, naming the file, as a --view file's would be.
    let forged = dir.path().join("forged.sndf");
    let bytes = std::fs::read(&sndf).unwrap();
    let j = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let data_at = (24 + j).div_ceil(16) * 16;
    let mut header: serde_json::Value = serde_json::from_slice(&bytes[24..24 + j]).unwrap();
    header["view"]["fov_y_deg"] = 0.0.into();
    let text = serde_json::to_vec(&header).unwrap();
    let mut out = bytes[..12].to_vec();
    out.extend_from_slice(&(text.len() as u32).to_le_bytes());
    out.extend_from_slice(&bytes[16..24]);
    out.extend_from_slice(&text);
    out.resize((24 + text.len()).div_ceil(16) * 16, 0);
    out.extend_from_slice(&bytes[data_at..]);
    std::fs::write(&forged, out).unwrap();
    let png = dir.path().join("forged.png");
    for args in [
        vec!["shade", s(&forged), "-o", s(&png)],
        vec!["info", s(&forged)],
    ] {
        let e = fails(&args);
        assert!(
            e.contains("forged.sndf: the camera in its header: fov_y_deg 0"),
            "{args:?}: {e}"
        );
    }
    // Cut inside its fixed header: an .sndf cut short, not "no S-NDF signature".
    let cut = dir.path().join("cut.sndf");
    std::fs::write(&cut, &std::fs::read(&sndf).unwrap()[..8]).unwrap();
    for args in [vec!["info", s(&cut)], vec!["shade", s(&cut), "-o", s(&png)]] {
        let e = fails(&args);
        assert!(
            e.contains("an .sndf file cut short: 8 bytes"),
            "{args:?}: {e}"
        );
    }
    // An .sndf where an .mdlod is read says what it is and what reads it.
    for cmd in ["render", "verify"] {
        let png = dir.path().join("wrong.png");
        let mut args = vec![cmd, s(&sndf)];
        if cmd == "render" {
            args.extend(["-o", s(&png)]);
        }
        let e = fails(&args);
        assert!(
            e.contains("view.sndf: an S-NDF file") && e.contains("`mdlod shade` lights it"),
            "{cmd}: {e}"
        );
    }
    let direct = dir.path().join("direct.png");
    let rendered = ok(&[
        &[
            "render",
            s(&mdlod),
            "-o",
            s(&direct),
            "--mode",
            "sndf",
            "--iterations",
            "8",
            "--binning",
            "lambert",
        ][..],
        &size,
    ]
    .concat());
    assert!(!rendered.contains("cluster spheres up to"), "{rendered}");
    // A coarse cut's S-NDFs are its cluster spheres': said.
    let coarse = dir.path().join("coarse.png");
    let out = ok(&[
        &[
            "render",
            s(&mdlod),
            "-o",
            s(&coarse),
            "--mode",
            "sndf",
            "--iterations",
            "1",
            "--screen-error",
            "500",
        ][..],
        &size,
    ]
    .concat());
    assert!(
        out.contains("note: the S-NDFs sample") && out.contains("whose normals are the spheres'"),
        "{out}"
    );
    // Without the particle data: the same picture from the S-NDFs, then re-lit.
    std::fs::remove_file(&mdlod).unwrap();
    let shaded = dir.path().join("shaded.png");
    let out = ok(&["shade", s(&sndf), "-o", s(&shaded)]);
    assert!(out.contains("no particle data read"), "{out}");
    assert_eq!(
        std::fs::read(&shaded).unwrap(),
        std::fs::read(&direct).unwrap()
    );
    let relit = dir.path().join("relit.png");
    ok(&[
        "shade",
        s(&sndf),
        "-o",
        s(&relit),
        "--light",
        "-1,0.2,0.5:#ff8040",
        "--light",
        "1,1,1",
        "--brdf",
        "lambert",
        "--level",
        "1",
    ]);
    let (w, h, px) = read_png(&relit);
    assert_eq!((w, h), (48, 32));
    let (_, _, before) = read_png(&shaded);
    assert_ne!(px.len(), before.len());
    // The lights and the BRDF take effect: the same level under the default light, and
    // under the same lights with highlights, differ from it.
    let level = |name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let mut args = vec!["shade", s(&sndf), "-o", s(&out), "--level", "1"];
        args.extend_from_slice(extra);
        ok(&args);
        read_png(&out).2
    };
    assert_ne!(level("default-lit.png", &[]), px, "--light was ignored");
    let phong = level(
        "phong.png",
        &[
            "--light",
            "-1,0.2,0.5:#ff8040",
            "--light",
            "1,1,1",
            "--brdf",
            "blinn-phong",
            "--specular",
            "0.8",
        ],
    );
    assert_ne!(phong, px, "--brdf was ignored");
    // The explorer pattern and an environment map, also without the particles.
    let explored = dir.path().join("explored.png");
    ok(&["shade", s(&sndf), "-o", s(&explored), "--explorer", "6"]);
    assert_ne!(read_png(&explored).2, read_png(&shaded).2);
    let env = dir.path().join("env.png");
    let mut sky = mdlod_render::RgbaImage::new(8, 4);
    for y in 0..4 {
        for x in 0..8 {
            sky.set_pixel(
                x,
                y,
                if y < 2 {
                    [255, 220, 160, 255]
                } else {
                    [30, 60, 140, 255]
                },
            );
        }
    }
    sky.save_png(&env).unwrap();
    let lit = dir.path().join("env-lit.png");
    let out = ok(&["shade", s(&sndf), "-o", s(&lit), "--envmap", s(&env)]);
    assert!(out.contains("lit by the environment map"), "{out}");
    assert_ne!(read_png(&lit).2, read_png(&shaded).2);
    // A painted transfer function: one green texel colours every normal green, so no
    // pixel has more red or blue than the white background blended in.
    let painted = dir.path().join("disk.png");
    let mut disk = mdlod_render::RgbaImage::new(1, 1);
    disk.set_pixel(0, 0, [0, 255, 0, 255]);
    disk.save_png(&painted).unwrap();
    let green = dir.path().join("green.png");
    ok(&[
        "shade",
        s(&sndf),
        "-o",
        s(&green),
        "--transfer",
        s(&painted),
    ]);
    let (_, _, g) = read_png(&green);
    let pixels: Vec<&[u8]> = g.chunks_exact(4).collect();
    assert!(
        pixels.iter().any(|p| p[..3] == [0, 255, 0]),
        "no fully covered green pixel"
    );
    assert!(pixels.iter().all(|p| p[1] >= p[0] && p[1] >= p[2]));
    // Options that change nothing in the image asked for are refused, not ignored.
    for (extra, says) in [
        (
            &["--explorer", "6", "--light", "1,1,1:#ff0000"][..],
            "--light has no effect with --explorer",
        ),
        (
            &["--transfer", s(&painted), "--ambient", "0.9"][..],
            "--ambient has no effect with --transfer",
        ),
        (
            &["--brdf", "lambert", "--exponent", "2"][..],
            "--exponent has no effect with --brdf lambert",
        ),
        (
            &["--explorer-disk", "10"][..],
            "--explorer-disk has no effect without --explorer",
        ),
        (
            &["--envmap", s(&painted), "--specular", "0.9"][..],
            "--specular has no effect with --envmap and no --light",
        ),
    ] {
        let mut args = vec!["shade", s(&sndf), "-o", s(&green)];
        args.extend_from_slice(extra);
        let e = fails(&args);
        assert!(e.contains(says), "{extra:?}: {e}");
    }
    let info = ok(&["info", s(&sndf)]);
    assert!(
        info.contains("96x64 texels, 8x8 lambert-equal-area bins, 8 rays each"),
        "{info}"
    );
    // The camera's numbers in their single-precision shortest form.
    let view = info.lines().find(|l| l.contains("view ")).unwrap();
    let digits = view
        .split(|c: char| !c.is_ascii_digit() && c != '.')
        .map(|n| n.trim_start_matches('.').len())
        .max()
        .unwrap_or(0);
    assert!(digits <= 10, "{view}");
    // Sampled finer so that every atom gets enough samples; shown at the asked size.
    let fine = dir.path().join("fine.sndf");
    ok(&[
        "convert",
        s(&lammps_sample_path("cu_melt.custom.dump")),
        "-o",
        s(&mdlod),
        "--radius",
        "1=1.28",
    ]);
    let out = ok(&[
        "sample",
        s(&mdlod),
        "-o",
        s(&fine),
        "--width",
        "40",
        "--height",
        "30",
        "--iterations",
        "2",
        "--min-samples",
        "32",
    ]);
    assert!(
        out.contains("sampled at") && out.contains("shown at level"),
        "{out}"
    );
    let shown = dir.path().join("shown.png");
    ok(&["shade", s(&fine), "-o", s(&shown)]);
    assert_eq!(read_png(&shown).0, 40);
    let finest = dir.path().join("finest.png");
    ok(&["shade", s(&fine), "-o", s(&finest), "--level", "0"]);
    assert!(read_png(&finest).0 > 40);
    // A damaged file is refused, naming it.
    let mut bytes = std::fs::read(&sndf).unwrap();
    let last = bytes.len() - 3;
    bytes[last] ^= 0x55;
    std::fs::write(&sndf, bytes).unwrap();
    let err = fails(&["shade", s(&sndf), "-o", s(&relit)]);
    assert!(
        err.contains("view.sndf") && err.contains("checksum"),
        "{err}"
    );
}

/// Names in `dir` that an out-of-core conversion leaves only while it runs.
/// `generate` writes its dump under a temporary name and renames it when complete:
/// stopped half way (Ctrl-C), it leaves nothing, not a partial dump under the output's
/// name that a batch would read as a run still writing it.
#[test]
fn an_interrupted_generate_leaves_no_partial_dump() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("big.lammpstrj");
    let mut child = Command::new(env!("CARGO_BIN_EXE_mdlod"))
        .args(["generate", "crater", "-n", "100000000", "-o", s(&out)])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Interrupted once its temporary file holds some text.
    let started = std::time::Instant::now();
    let written = || {
        std::fs::read_dir(dir.path())
            .unwrap()
            .flatten()
            .any(|e| e.metadata().is_ok_and(|m| m.len() > 0))
    };
    while !written() {
        assert!(started.elapsed().as_secs() < 60, "generate wrote nothing");
        assert!(child.try_wait().unwrap().is_none(), "generate ended early");
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    assert!(
        !out.exists(),
        "the dump is written under its name as it is generated"
    );
    let done = ctrl_c(child);
    assert_eq!(done.status.code(), Some(130));
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().flatten().collect();
    assert!(left.is_empty(), "{left:?}");
    // Complete, it is there under its name alone.
    generate(&["crater", "-n", "2000"], &out);
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, ["big.lammpstrj"]);
}

/// Sends `child` Ctrl-C (SIGINT) and waits for it to end.
fn ctrl_c(child: std::process::Child) -> Output {
    let status = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    child.wait_with_output().unwrap()
}

fn working_entries(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".mdlod-convert-") || n.ends_with(".tmp"))
        .collect()
}

#[test]
fn out_of_core_conversion_ignores_the_memory_limit_and_cleans_up_on_ctrl_c() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("alloy.raw.json");
    let made = generate(&["alloy", "-n", "120000", "--format", "raw"], &input);
    assert!(made.contains("120000 particles"), "{made}");
    // Chunks of 30 000: one at a time under 68 MiB, whose chunk results then go through
    // working files; both threads with 8 GiB, which keeps the results in memory.
    let convert = |out: &Path, limit: &str, threads: &str| {
        ok(&[
            "convert",
            s(&input),
            "-o",
            s(out),
            "--radius",
            "1=1.28",
            "--radius",
            "2=1.44",
            "--root-points",
            "256",
            "--chunk-points",
            "30000",
            "--memory-limit",
            limit,
            "--threads",
            threads,
        ])
    };
    let (a, b) = (dir.path().join("a.mdlod"), dir.path().join("b.mdlod"));
    convert(&a, "68M", "1");
    convert(&b, "8G", "2");
    assert!(std::fs::read(&a).unwrap() == std::fs::read(&b).unwrap());
    let info = ok(&["info", s(&a), "--json"]);
    let v: serde_json::Value = serde_json::from_str(&info).unwrap();
    assert_eq!(v["build"]["chunk_points"], 30000, "{info}");
    assert_eq!(v["particles"], 120000, "{info}");
    ok(&["verify", s(&a)]);
    assert!(working_entries(dir.path()).is_empty());

    // A limit below one chunk is refused before any work, naming the need.
    let err = fails(&[
        "convert",
        s(&input),
        "-o",
        s(&dir.path().join("c.mdlod")),
        "--chunk-points",
        "30000",
        "--root-points",
        "256",
        "--memory-limit",
        "10M",
    ]);
    assert!(err.contains("memory limit of 10 MiB"), "{err}");
    assert!(working_entries(dir.path()).is_empty());

    // A frame within the chunk size is built in memory: a limit below what that needs
    // is refused before the frame is read (out of core would need more than 12 MiB
    // too); a limit of 0 is no limit to work within.
    let c = dir.path().join("c.mdlod");
    let err = fails(&["convert", s(&input), "-o", s(&c), "--memory-limit", "12M"]);
    assert!(
        err.contains("alloy.raw.json")
            && err.contains("120000 particles are built in memory")
            && err.contains("need about 17 MiB, above the memory limit of 12 MiB")
            && err.trim_end().ends_with("raise --memory-limit"),
        "{err}"
    );
    let err = fails(&["convert", s(&input), "-o", s(&c), "--memory-limit", "0"]);
    assert!(err.contains("leaves no room"), "{err}");
    assert!(!c.exists());
    assert!(working_entries(dir.path()).is_empty());

    // Ctrl-C while chunks are being built removes the working files and the partial
    // output.
    let out = dir.path().join("interrupted.mdlod");
    let child = convert_until_chunks_are_built(dir.path(), &input, &out);
    let done = ctrl_c(child);
    assert_eq!(
        done.status.code(),
        Some(130),
        "{}",
        String::from_utf8_lossy(&done.stderr)
    );
    assert!(!out.exists());
    assert!(
        working_entries(dir.path()).is_empty(),
        "{:?}",
        working_entries(dir.path())
    );

    // SIGKILL leaves the working directory (nothing can run); the next conversion on this
    // host removes it, since its process is gone.
    let mut child = convert_until_chunks_are_built(dir.path(), &input, &out);
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(!working_entries(dir.path()).is_empty());
    ok(&[
        "convert",
        s(&input),
        "-o",
        s(&out),
        "--chunk-points",
        "30000",
        "--root-points",
        "256",
    ]);
    assert!(
        working_entries(dir.path()).is_empty(),
        "{:?}",
        working_entries(dir.path())
    );
    ok(&["verify", s(&out)]);
}

/// Starts an out-of-core conversion of `input` (in `dir`) into `out` and returns once its
/// working directory holds built chunks.
fn convert_until_chunks_are_built(dir: &Path, input: &Path, out: &Path) -> std::process::Child {
    let mut child = Command::new(env!("CARGO_BIN_EXE_mdlod"))
        .args([
            "convert",
            s(input),
            "-o",
            s(out),
            "--chunk-points",
            "5000",
            "--root-points",
            "64",
            "--threads",
            "1",
            // No room to keep chunk results in memory: they go to working files, which
            // tell that chunks were built.
            "--memory-limit",
            "66M",
        ])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let started = std::time::Instant::now();
    while !working_entries(dir)
        .iter()
        .filter(|n| n.starts_with(".mdlod-convert-"))
        .flat_map(|n| walk(&dir.join(n)))
        .any(|f| f.contains("chunk-"))
    {
        assert!(
            child.try_wait().unwrap().is_none(),
            "the conversion ended before chunks were built"
        );
        assert!(started.elapsed().as_secs() < 60, "no chunks after a minute");
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    child
}

/// Every file name below `dir` (empty when it is gone).
fn walk(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    if let Ok(entries) = std::fs::read_dir(dir) {
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                out.extend(walk(&p));
            } else {
                out.push(e.file_name().to_string_lossy().into_owned());
            }
        }
    }
    out
}

/// The look options: a colour map by the attribute and restyled species give other
/// pictures of the same view; a species the file lacks, a colour map without an
/// attribute and a bad value are clear errors.
#[test]
fn render_styles_points_by_attribute_and_species() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let dump = d.join("a.lammpstrj");
    ok(&["generate", "alloy", "-n", "4000", "-o", s(&dump)]);
    let with = d.join("with.mdlod");
    let without = d.join("without.mdlod");
    ok(&["convert", s(&dump), "-o", s(&with), "--attribute", "c_pe"]);
    ok(&["convert", s(&dump), "-o", s(&without)]);
    let png = |name: &str, extra: &[&str]| {
        let out = d.join(name);
        let mut args = vec![
            "render",
            s(&with),
            "-o",
            s(&out),
            "--width",
            "96",
            "--height",
            "72",
        ];
        args.extend_from_slice(extra);
        ok(&args);
        read_png(&out).2
    };
    let plain = png("plain.png", &[]);
    let mapped = png("mapped.png", &["--colour-map", "viridis"]);
    let hidden = png(
        "hidden.png",
        &["--hide-species", "2", "--radius-scale", "0.8"],
    );
    let recoloured = png("recoloured.png", &["--species-colour", "1=#00ff00"]);
    // The summary says how many particles of hidden species were left out.
    let out = ok(&[
        "render",
        s(&with),
        "-o",
        s(&d.join("h.png")),
        "--width",
        "32",
        "--height",
        "24",
        "--hide-species",
        "2",
        "--screen-error",
        "0",
    ]);
    let count = |what: &str| -> u64 {
        let i = out.find(what).unwrap_or_else(|| panic!("{what}: {out}"));
        let digits: String = out[..i]
            .chars()
            .rev()
            .skip(1)
            .take_while(char::is_ascii_digit)
            .collect();
        digits.chars().rev().collect::<String>().parse().unwrap()
    };
    let (all, hidden_count) = (count("particles ("), count("of hidden species"));
    let file = mdlod_format::MdlodFile::open(&with).unwrap();
    let species_2 = file.species().iter().filter(|&&i| i == 1).count() as u64;
    assert!(
        all + hidden_count == file.particle_count() && hidden_count == species_2,
        "{out}"
    );
    for other in [&mapped, &hidden, &recoloured] {
        assert_ne!(&plain, other);
    }
    // Recolouring species 1 green: green now dominates.
    let greenish = |img: &[u8]| {
        img.chunks_exact(4)
            .filter(|p| p[1] > p[0].saturating_add(40) && p[1] > p[2].saturating_add(40))
            .count()
    };
    assert!(greenish(&recoloured) > 10 * greenish(&plain).max(1));
    // Under a colour map (magma: no green), a species given its colour keeps it: its
    // atoms green among the others' map colours (a DEM figure's walls beside grains).
    let magma = png("magma.png", &["--colour-map", "magma"]);
    let kept = png(
        "kept.png",
        &["--colour-map", "magma", "--species-colour", "2=#00ff00"],
    );
    assert_eq!(greenish(&magma), 0);
    assert!(greenish(&kept) > 20, "{}", greenish(&kept));
    // The others keep the map's dark colours (the alloy's copper sits near its low end).
    let dark = |img: &[u8]| img.chunks_exact(4).filter(|p| p[1] < 60).count();
    assert!(dark(&kept) > 500, "{}", dark(&kept));
    // A projection colours the pixels' light, not the particles.
    let err = fails(&[
        "render",
        s(&with),
        "-o",
        s(&d.join("x.png")),
        "--mode",
        "splat",
        "--colour-map",
        "magma",
        "--species-colour",
        "2=#00ff00",
    ]);
    assert!(
        err.contains("--species-colour has no effect on a projection"),
        "{err}"
    );
    let err = fails(&[
        "render",
        s(&with),
        "-o",
        s(&d.join("x.png")),
        "--species-radius",
        "Xx=2",
    ]);
    assert!(err.contains("\"Xx\"") && err.contains("1, 2"), "{err}");
    let err = fails(&[
        "render",
        s(&without),
        "-o",
        s(&d.join("x.png")),
        "--colour-map",
        "magma",
    ]);
    assert!(
        err.contains("no per-particle attribute") && err.contains("without.mdlod"),
        "{err}"
    );
    let err = fails(&[
        "render",
        s(&with),
        "-o",
        s(&d.join("x.png")),
        "--species-radius",
        "1=-2",
    ]);
    assert!(err.contains("radius"), "{err}");
    assert!(!d.join("x.png").exists());
}

#[test]
fn an_output_onto_an_input_or_a_directory_is_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("dump.lammpstrj");
    std::fs::copy(lammps_sample_path("cu_melt.custom.dump"), &dump).unwrap();
    let frame = converted(dir.path(), "cu_melt.custom.dump");
    let view = dir.path().join("v.json");
    std::fs::write(&view, r#"{"version": 1}"#).unwrap();
    let sndf = dir.path().join("v.sndf");
    std::fs::write(&sndf, "not read: the output is refused first").unwrap();
    let png = dir.path().join("x.png");
    let sub = dir.path().join("outdir");
    std::fs::create_dir(&sub).unwrap();
    let before = |p: &Path| std::fs::read(p).unwrap();
    let (dump0, frame0, view0, sndf0) =
        (before(&dump), before(&frame), before(&view), before(&sndf));
    // The same file, also under another spelling of its path.
    let dotted = dir.path().join(".").join("dump.lammpstrj");
    for args in [
        vec!["convert", s(&dump), "-o", s(&dump)],
        vec!["convert", s(&dump), "-o", s(&dotted)],
        vec!["render", s(&frame), "-o", s(&frame)],
        vec!["render", s(&frame), "-o", s(&view), "--view", s(&view)],
        vec!["render", s(&frame), "-o", s(&png), "--save-view", s(&frame)],
        vec!["sample", s(&frame), "-o", s(&frame)],
        vec!["shade", s(&sndf), "-o", s(&sndf)],
    ] {
        let err = fails(&args);
        assert!(
            err.contains("is the input") || err.contains("is the --view file"),
            "{args:?}: {err}"
        );
        assert!(err.contains("give another output path"), "{args:?}: {err}");
    }
    let err = fails(&["render", s(&frame), "-o", s(&png), "--save-view", s(&png)]);
    assert!(err.contains("is the -o output too"), "{err}");
    assert_eq!(
        (before(&dump), before(&frame), before(&view), before(&sndf)),
        (dump0, frame0, view0, sndf0),
        "an input changed"
    );
    assert!(!png.exists());
    // A directory as the output is refused at the start, naming it.
    for args in [
        vec!["convert", s(&dump), "-o", s(&sub)],
        vec!["render", s(&frame), "-o", s(&sub)],
        vec!["sample", s(&frame), "-o", s(&sub)],
        vec!["shade", s(&sndf), "-o", s(&sub)],
    ] {
        let err = fails(&args);
        assert!(
            err.contains(&format!("-o {}: is a directory; give the name", s(&sub))),
            "{args:?}: {err}"
        );
    }
    assert_eq!(std::fs::read_dir(&sub).unwrap().count(), 0);
    // A batch directory that holds an input under a frame's name, or is a file.
    let d = dir.path().join("batch.d");
    std::fs::create_dir(&d).unwrap();
    let inside = d.join("frame-0.mdlod");
    std::fs::copy(&dump, &inside).unwrap();
    let err = fails(&["batch", s(&inside), "-o", s(&d)]);
    assert!(err.contains("in the batch directory"), "{err}");
    assert_eq!(before(&inside), before(&dump));
    let err = fails(&["batch", s(&dump), "-o", s(&dump)]);
    assert!(err.contains("is not a directory"), "{err}");
    assert_eq!(
        before(&dump),
        before(&lammps_sample_path("cu_melt.custom.dump"))
    );
}

#[test]
fn radius_overrides_naming_no_species_are_errors_listing_the_species() {
    let dir = tempfile::tempdir().unwrap();
    let input = lammps_sample_path("cu_melt.custom.dump");
    let out = dir.path().join("a.mdlod");
    // The dump has numeric type 1 only: `Cu` names nothing.
    let err = fails(&["convert", s(&input), "-o", s(&out), "--radius", "Cu=1.28"]);
    assert!(
        err.contains("no species named \"Cu\"") && err.contains("the input's species are named 1"),
        "{err}"
    );
    assert!(!out.exists());
    ok(&["convert", s(&input), "-o", s(&out), "--radius", "1=1.28"]);
    // A batch: an override naming a species no frame holds (a species may appear in
    // some frames only), also when a previous run finished every frame.
    let d = dir.path().join("b.d");
    let err = fails(&["batch", s(&input), "-o", s(&d), "--radius", "Cu=1.28"]);
    assert!(err.contains("no species named \"Cu\""), "{err}");
    ok(&["batch", s(&input), "-o", s(&d), "--radius", "1=1.28"]);
    let err = fails(&[
        "batch",
        s(&input),
        "-o",
        s(&d),
        "--radius",
        "1=1.28",
        "--radius",
        "cu=1",
    ]);
    assert!(err.contains("no species named \"cu\""), "{err}");
}

#[test]
fn options_the_chosen_mode_does_not_read_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let frame = converted(dir.path(), "cu_melt.custom.dump");
    let png = dir.path().join("x.png");
    let (f, p) = (s(&frame), s(&png));
    for (extra, message) in [
        (
            vec!["--mode", "density", "--radius-scale", "2"],
            "--radius-scale has no effect with --mode density: it applies to --mode spheres or sndf",
        ),
        (
            vec!["--mode", "splat", "--spp", "4"],
            "--spp has no effect with --mode splat: it applies to --mode spheres",
        ),
        (
            vec!["--mode", "iso", "--absorption", "0.3"],
            "--absorption has no effect with --mode iso: it applies to --mode density",
        ),
        (
            vec!["--iterations", "4"],
            "--iterations has no effect with --mode spheres: it applies to --mode sndf",
        ),
        (
            vec!["--kernel-scale", "1"],
            "--kernel-scale has no effect with --mode spheres: it applies to --mode density or iso or splat or splat-over",
        ),
        (
            vec!["--mode", "splat-over", "--colour-map", "magma"],
            "--colour-map has no effect with --mode splat-over",
        ),
        (
            vec!["--mode", "iso", "--log-scale"],
            "--log-scale has no effect without --colour-map (spheres, sndf, splat, density, iso) or \
             --intensity attribute (splat); with --mode density and no colour map it takes",
        ),
        (
            vec!["--density-min", "0.1"],
            "--density-min has no effect with --mode spheres: it applies to --mode density",
        ),
        (
            vec!["--mode", "density", "--density-min", "1"],
            "--density-min 1 at or above --density-max 0.8",
        ),
        (
            vec!["--mode", "density", "--log-scale", "--density-min", "0"],
            "--density-min 0 on a log scale (must be above 0",
        ),
        (
            vec!["--mode", "density", "--log-scale", "--density-max=1e-41"],
            "four decades below it (a log scale's default bottom) is below single precision",
        ),
        (
            vec!["--cell-width", "3"],
            "--cell-width has no effect without --cell: it sets the width of the cell's edges",
        ),
    ] {
        let mut args = vec!["render", f, "-o", p];
        args.extend(extra);
        let err = fails(&args);
        assert!(err.contains(message), "{args:?}: {err}");
        assert!(!png.exists(), "{args:?} wrote an image");
    }
    // The same options with their modes pass the check (and fail later, at a size
    // check that needs no GPU).
    for extra in [
        vec!["--mode", "density", "--slices", "8", "--absorption", "0.3"],
        vec!["--mode", "iso", "--kernel-scale", "2", "--iso-value", "0.2"],
        vec!["--mode", "splat", "--kernel-scale", "1"],
        vec!["--mode", "splat-over", "--kernel-scale", "2"],
        vec![
            "--mode",
            "splat",
            "--exposure",
            "2",
            "--intensity",
            "attribute",
        ],
        vec!["--mode", "sndf", "--iterations", "4", "--radius-scale", "2"],
        vec![
            "--spp",
            "4",
            "--species-colour",
            "1=#ff0000",
            "--no-occlusion",
        ],
    ] {
        let mut args = vec!["render", f, "-o", p, "--width", "40000"];
        args.extend(extra);
        let err = fails(&args);
        assert!(err.contains("must each be 1 to 32768"), "{args:?}: {err}");
    }
}

/// `--hide-attribute`: particles of the values given are left out (the summary says how
/// many, by value); a range hiding every value says why nothing is drawn; bad ranges and
/// a file without an attribute are refused.
#[test]
fn particles_are_hidden_by_their_values() {
    let dir = tempfile::tempdir().unwrap();
    let input = mdlod_datasets::lammps_sample_path("cu_melt.custom.dump");
    let file = dir.path().join("pe.mdlod");
    ok(&[
        "convert",
        s(&input),
        "-o",
        s(&file),
        "--last",
        "--attribute",
        "c_pe",
    ]);
    let png = dir.path().join("x.png");
    let render = |extra: &[&str]| {
        let mut args = vec![
            "render",
            s(&file),
            "-o",
            s(&png),
            "--width",
            "48",
            "--height",
            "32",
        ];
        args.extend_from_slice(extra);
        args.iter().map(|a| a.to_string()).collect::<Vec<_>>()
    };
    let run = |extra: &[&str]| {
        let args = render(extra);
        ok(&args.iter().map(String::as_str).collect::<Vec<_>>())
    };
    let drawn = |out: &str| -> u64 {
        let at = out.find(" particles").unwrap();
        out[..at].rsplit(' ').next().unwrap().parse().unwrap()
    };
    let all = drawn(&run(&["--screen-error", "0", "--no-occlusion"]));
    let out = run(&["--screen-error", "0", "--hide-attribute", "-3.3:"]);
    let some = drawn(&out);
    assert!(some > 0 && some < all, "{some} of {all}: {out}");
    assert!(
        out.contains(&format!(
            "{} with hidden values (--hide-attribute) left out",
            all - some
        )),
        "{out}"
    );
    let out = run(&["--hide-attribute", ":0"]);
    assert!(
        out.contains("nothing is drawn: every particle in view has a value --hide-attribute hides"),
        "{out}"
    );
    for (range, message) in [
        (":", "both ends open"),
        ("2:1", "MAX must not be below MIN"),
        ("1", "expected MIN:MAX"),
        ("a:1", "is not a number in single precision"),
    ] {
        let args = render(&["--hide-attribute", range]);
        let e = fails(&args.iter().map(String::as_str).collect::<Vec<_>>());
        assert!(e.contains(message), "{range}: {e}");
    }
    let plain = dir.path().join("plain.mdlod");
    ok(&["convert", s(&input), "-o", s(&plain), "--last"]);
    let e = fails(&[
        "render",
        s(&plain),
        "-o",
        s(&png),
        "--hide-attribute",
        "0:1",
    ]);
    assert!(
        e.contains("no per-particle attribute to hide particles by"),
        "{e}"
    ); // A column of structure types 1 to 5: `2:2` hides exactly the 2s, though the file
       // stores them as 2.00006; a range beside the values hides nothing, and says so.
    let mut dump = String::from(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n125\nITEM: BOX BOUNDS pp pp pp\n0 10\n0 10\n0 10\n\
         ITEM: ATOMS id type x y z c_cna\n",
    );
    for i in 0..125 {
        let (x, y, z) = (i % 5, (i / 5) % 5, i / 25);
        dump += &format!("{} 1 {} {} {} {}\n", i + 1, 2 * x, 2 * y, 2 * z, 1 + i % 5);
    }
    let cna = dir.path().join("cna.dump");
    std::fs::write(&cna, dump).unwrap();
    let cna_file = dir.path().join("cna.mdlod");
    ok(&[
        "convert",
        s(&cna),
        "-o",
        s(&cna_file),
        "--attribute",
        "c_cna",
    ]);
    let drawn_of = |extra: &[&str]| {
        let mut args = vec![
            "render",
            s(&cna_file),
            "-o",
            s(&png),
            "--width",
            "48",
            "--height",
            "32",
        ];
        args.extend_from_slice(extra);
        let out = ok(&args);
        (drawn(&out), out)
    };
    for (range, kept) in [("2:2", 100), ("1:2", 75), ("4:", 75), (":1", 100)] {
        let (n, out) = drawn_of(&["--screen-error", "0", "--hide-attribute", range]);
        assert_eq!(n, kept, "{range}: {out}");
    }
    let (n, out) = drawn_of(&["--screen-error", "0", "--hide-attribute", "6:9"]);
    assert!(
        n == 125 && out.contains("--hide-attribute hides no particle: c_cna lies from 1 to 5"),
        "{out}"
    );
    // A range within the attribute's range but between its values hides nothing either,
    // and says so.
    // Beside a range that hides some, one that hides none is named.
    let (n, out) = drawn_of(&[
        "--screen-error",
        "0",
        "--hide-attribute",
        "2.2:2.8",
        "--hide-attribute",
        "1:1",
    ]);
    assert!(
        n == 100
            && out.contains(
                "--hide-attribute range 2.2:2.8 hides no particle: no value of c_cna lies in it \
                 here"
            ),
        "{out}"
    );
    let (n, out) = drawn_of(&["--screen-error", "0", "--hide-attribute", "2.2:2.8"]);
    assert!(
        n == 125
            && out.contains(
                "--hide-attribute hides no particle: c_cna lies from 1 to 5 here, and none of \
                 its values lies in the range"
            ),
        "{out}"
    );
}

/// The real bicrystal's common-neighbour analysis (`datasets/lammps/cu_gb.cna.dump`):
/// hiding its fcc atoms draws exactly its other atoms, the boundaries, as many as the
/// dump holds, at every screen error (clusters of fcc atoms only are culled, mixed ones
/// opened).
#[test]
fn hiding_a_real_bicrystals_fcc_atoms_leaves_its_boundaries() {
    let dir = tempfile::tempdir().unwrap();
    let input = lammps_sample_path("cu_gb.cna.dump");
    let cna = mdlod_datasets::lammps_sample_column("cu_gb.cna.dump", "c_cna");
    let other = cna.iter().filter(|v| *v != "1").count();
    assert!(
        other > 100 && other < cna.len() / 2,
        "{other} of {}",
        cna.len()
    );
    let file = dir.path().join("gb.mdlod");
    ok(&["convert", s(&input), "-o", s(&file), "--attribute", "c_cna"]);
    let png = dir.path().join("gb.png");
    draws_the_boundaries(&file, &png, &["--hide-attribute", "0.5:1.5"], other as u64);
}

/// Renders the bicrystal `file` with `hide` (its fcc atoms hidden) at 0, 4 and 16 px:
/// exactly its `other` boundary atoms at 0 px (with those behind others), at most as
/// many coarser (clusters of boundary atoms only stand in for some), none holding fcc.
fn draws_the_boundaries(file: &Path, png: &Path, hide: &[&str], other: u64) {
    for error in ["0", "4", "16"] {
        let mut args = vec![
            "render",
            s(file),
            "-o",
            s(png),
            "--width",
            "96",
            "--height",
            "64",
            "--screen-error",
            error,
            "--budget",
            "1000000",
            "--no-occlusion",
        ];
        args.extend_from_slice(hide);
        let out = ok(&args);
        let drawn: u64 = {
            let at = out.find(" particles").unwrap();
            out[..at].rsplit(' ').next().unwrap().parse().unwrap()
        };
        if error == "0" {
            assert_eq!(drawn, other, "{out}");
        } else {
            assert!(drawn <= other, "{out}");
        }
        assert!(!out.contains("still hold"), "{out}");
    }
}

/// The real bicrystal coloured by structure (`--species-column c_cna`): each structure
/// type is a species, named, sized as the dump's element, hidden as species are (exactly
/// the dump's non-fcc atoms drawn at 0 px, no fcc atom coarser), the same in chunks as
/// whole, in text and binary; a continuous column gets a note, a radius for the element a
/// hint.
#[test]
fn a_real_bicrystal_coloured_and_hidden_by_its_structure_types() {
    let dir = tempfile::tempdir().unwrap();
    let input = lammps_sample_path("cu_gb.cna.dump");
    let cna = mdlod_datasets::lammps_sample_column("cu_gb.cna.dump", "c_cna");
    let other = cna.iter().filter(|v| *v != "1").count() as u64;
    // (The dump's atoms, every one with its analysis.)
    assert_eq!(cna.len(), 2552);
    let names = ["--species-name", "1=FCC", "--species-name", "5=Other"];
    let species_of = |file: &Path| -> Vec<(String, f32, u64)> {
        let f = MdlodFile::open(file).unwrap();
        let m = f.metadata();
        let mut counts = vec![0u64; m.species.len()];
        for &k in f.species() {
            counts[usize::from(k)] += 1;
        }
        m.species
            .iter()
            .zip(counts)
            .map(|(s, n)| (s.name.clone(), s.radius, n))
            .collect()
    };
    let whole = dir.path().join("gb.mdlod");
    let mut args = vec![
        "convert",
        s(&input),
        "-o",
        s(&whole),
        "--species-column",
        "c_cna",
    ];
    args.extend_from_slice(&names);
    ok(&args);
    let expected = vec![
        ("FCC".to_string(), 1.28, 2552 - other),
        ("Other".to_string(), 1.28, other),
    ];
    assert_eq!(species_of(&whole), expected);
    // In chunks, and from the binary dump of the same step (no elements: sized by --radius).
    let chunked = dir.path().join("chunked.mdlod");
    let mut args = vec![
        "convert",
        s(&input),
        "-o",
        s(&chunked),
        "--species-column",
        "c_cna",
    ];
    args.extend_from_slice(&names);
    args.extend_from_slice(&["--chunk-points", "1000", "--root-points", "256"]);
    ok(&args);
    assert_eq!(species_of(&chunked), expected);
    let binary = dir.path().join("binary.mdlod");
    let bin = lammps_sample_path("cu_gb.cna.bin");
    let mut args = vec![
        "convert",
        s(&bin),
        "-o",
        s(&binary),
        "--species-column",
        "c_cna",
    ];
    args.extend_from_slice(&names);
    args.extend_from_slice(&["--radius", "FCC=1.28", "--radius", "Other=1.28"]);
    ok(&args);
    assert_eq!(species_of(&binary), expected);
    // Each file records where its species came from, and `info` says so.
    for file in [&whole, &chunked, &binary] {
        let f = MdlodFile::open(file).unwrap();
        assert_eq!(f.metadata().species_column.as_deref(), Some("c_cna"));
    }
    let info = ok(&["info", s(&whole)]);
    assert!(
        info.contains("species are the values of the input's column c_cna"),
        "{info}"
    );
    let plain = dir.path().join("plain.mdlod");
    ok(&["convert", s(&input), "-o", s(&plain)]);
    assert_eq!(
        MdlodFile::open(&plain).unwrap().metadata().species_column,
        None
    );
    assert!(!ok(&["info", s(&plain)]).contains("column"));
    // A structure type this frame lacks (a script over every frame of a run hides HCP):
    // noted, not refused; so is hiding or colouring a species a file of elements lacks.
    let png = dir.path().join("h.png");
    let mut args = vec!["render", s(&whole), "-o", s(&png), "--hide-species", "HCP"];
    args.extend(["--width", "32", "--height", "24"]);
    let out = ok(&args);
    assert!(
        out.contains(
            "note: no particle of this frame is HCP (its species are the values of c_cna: \
             FCC, Other)"
        ),
        "{out}"
    );
    let mut args = vec!["render", s(&plain), "-o", s(&png), "--hide-species", "HCP"];
    args.extend(["--width", "32", "--height", "24"]);
    assert!(ok(&args).contains("--hide-species HCP: no particle of this frame is HCP"));
    let mut args = vec![
        "render",
        s(&plain),
        "-o",
        s(&png),
        "--species-colour",
        "HCP=red",
    ];
    args.extend(["--width", "32", "--height", "24"]);
    assert!(ok(&args).contains("note: no particle of this frame is HCP"));
    // A type of the frame spelt otherwise is a misspelling: refused, naming it.
    let mut args = vec!["render", s(&whole), "-o", s(&png), "--hide-species", "Fcc"];
    args.extend(["--width", "32", "--height", "24"]);
    let e = fails(&args);
    assert!(e.contains("did you mean \"FCC\""), "{e}");
    let png = dir.path().join("gb.png");
    for file in [&whole, &chunked] {
        draws_the_boundaries(file, &png, &["--hide-species", "FCC"], other);
    }
    // A continuous column: a species per value, and a note saying what the option takes.
    let pe = dir.path().join("pe.mdlod");
    let out = ok(&[
        "convert",
        s(&input),
        "-o",
        s(&pe),
        "--species-column",
        "c_pe",
    ]);
    assert!(
        out.contains("note: --species-column c_pe gave ")
            && out.contains("a continuous quantity goes in --attribute"),
        "{out}"
    );
    // A script naming every structure type, and a radius for the element, which is no
    // species now: converted, each named value the frame lacks noted.
    let out = ok(&[
        "convert",
        s(&input),
        "-o",
        s(&pe),
        "--species-column",
        "c_cna",
        "--species-name",
        "1=FCC",
        "--species-name",
        "2=HCP",
        "--species-name",
        "5=Other",
        "--radius",
        "Cu=1.3",
    ]);
    assert!(
        out.contains("note: --species-name 2=HCP: no particle has the value 2 in --species-column c_cna here (the species here: FCC, Other)")
            && out.contains("note: --radius Cu=1.3: no species Cu here")
            && !out.contains("1=FCC:"),
        "{out}"
    );
}

/// Mistakes a figure maker makes first: an option whose value needs `=`, a view file's
/// directory that is not there (said before a long render, not after), a numbered name
/// for one image, a target far from the data.
#[test]
fn first_mistakes_are_named_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let frame = converted(dir.path(), "cu_melt.custom.dump");
    let png = dir.path().join("x.png");
    let (f, p) = (s(&frame), s(&png));
    let err = fails(&["render", f, "-o", p, "--cell", "red"]);
    assert!(
        err.contains("unexpected argument 'red'")
            && err.contains("tip: --cell takes its value after an equals sign: --cell=red"),
        "{err}"
    );
    let err = fails(&["render", "--legend-in-image", "top-left", f, "-o", p]);
    assert!(err.contains("--legend-in-image=top-left"), "{err}");
    // Standard output is no file to write.
    let err = fails(&["render", f, "-o", "-"]);
    assert!(
        err.contains("mdlod writes a file, not standard output"),
        "{err}"
    );
    let err = fails(&["generate", "crater", "-n", "10", "-o", "-"]);
    assert!(
        err.contains("mdlod writes a file, not standard output"),
        "{err}"
    );
    let err = fails(&[
        "batch",
        s(&lammps_sample_path("cu_melt.custom.dump")),
        "-o",
        "-",
    ]);
    assert!(
        err.contains("a batch writes a directory, not standard output"),
        "{err}"
    );
    assert!(!Path::new("-").exists());
    // A panel's size with no panel to size.
    let err = fails(&["render", f, "-o", p, "--text-scale", "2"]);
    assert!(
        err.contains("--text-scale sizes the panels drawn into the image"),
        "{err}"
    );
    assert!(!png.exists());
    // No thread at all: said in words, not as a range of 64-bit numbers.
    let input = lammps_sample_path("cu_melt.custom.dump");
    let out = dir.path().join("t.mdlod");
    for command in ["convert", "batch"] {
        let err = fails(&[command, s(&input), "-o", s(&out), "--threads", "0"]);
        assert!(err.contains("at least 1 thread"), "{err}");
    }
    // Not where another argument is at fault (`--cell FILE` is right as it stands).
    let err = fails(&["render", "--cell", f, "-o", p, "--widht", "10"]);
    assert!(
        err.contains("unexpected argument '--widht'") && !err.contains("after an equals sign"),
        "{err}"
    );
    let view = dir.path().join("nodir").join("v.json");
    let err = fails(&["render", f, "-o", p, "--save-view", s(&view)]);
    assert!(err.contains("does not exist"), "{err}");
    assert!(!png.exists(), "the image was drawn before the check");
    let numbered = dir.path().join("x-%03d.png");
    let err = fails(&["render", f, "-o", s(&numbered)]);
    assert!(
        err.contains("numbered for a series") && err.contains("--turntable"),
        "{err}"
    );
    assert_eq!(
        std::fs::read_dir(dir.path())
            .unwrap()
            .filter(|e| e
                .as_ref()
                .unwrap()
                .path()
                .extension()
                .is_some_and(|x| x == "png"))
            .count(),
        0
    );
    let err = fails(&["render", f, "-o", p, "--target", "1e9,0,0"]);
    assert!(
        err.contains("target [1e9, 0, 0]") && err.contains("near the data"),
        "{err}"
    );
    // A turntable's view goes where its images go, created with them.
    let spin = dir.path().join("spin");
    ok(&[
        "render",
        f,
        "-o",
        s(&spin.join("v-%d.png")),
        "--turntable",
        "2",
        "--width",
        "24",
        "--height",
        "16",
        "--save-view",
        s(&spin.join("views").join("first.json")),
    ]);
    assert!(spin.join("views").join("first.json").is_file());
}

#[test]
fn options_are_checked_before_memory_or_work_goes_into_them() {
    let dir = tempfile::tempdir().unwrap();
    let frame = converted(dir.path(), "cu_melt.custom.dump");
    let png = dir.path().join("x.png");
    let f = s(&frame);
    let p = s(&png);
    // Absurd image sizes: refused before the traversal, naming the cap.
    for args in [
        vec!["render", f, "-o", p, "--width", "4000000000"],
        vec!["render", f, "-o", p, "--height", "40000", "--no-occlusion"],
        vec![
            "sample",
            f,
            "-o",
            p,
            "--width",
            "300000000",
            "--min-samples",
            "64",
        ],
        vec![
            "sample",
            f,
            "-o",
            p,
            "--width",
            "4000000000",
            "--tiles",
            "--ortho",
        ],
    ] {
        let err = fails(&args);
        assert!(err.contains("must each be 1 to 32768"), "{args:?}: {err}");
    }
    let err = fails(&[
        "sample",
        f,
        "-o",
        p,
        "--width",
        "32768",
        "--height",
        "32768",
        "--min-samples",
        "1000000000",
    ]);
    assert!(
        err.contains("--min-samples 1000000000") && err.contains("32768"),
        "{err}"
    );
    // Splat exposure and the screen error.
    for bad in ["nan", "-1", "0", "inf"] {
        let exposure = format!("--exposure={bad}");
        let err = fails(&["render", f, "-o", p, "--mode", "splat", &exposure]);
        assert!(
            err.contains("exposure") && err.contains("above 0"),
            "{bad}: {err}"
        );
    }
    let err = fails(&["render", f, "-o", p, "--screen-error", "inf"]);
    assert!(err.contains("a finite number, 0 or more"), "{err}");
    // Shading numbers (checked before the .sndf file is read).
    let sndf = dir.path().join("v.sndf");
    std::fs::write(&sndf, "x").unwrap();
    for option in ["--ambient", "--diffuse", "--specular", "--exponent"] {
        for bad in ["nan", "-1"] {
            let arg = format!("{option}={bad}");
            let err = fails(&["shade", s(&sndf), "-o", p, &arg]);
            assert!(
                err.contains(&format!(
                    "{option} {}",
                    if bad == "nan" { "NaN" } else { bad }
                )) && err.contains("finite number, 0 or more"),
                "{option} {bad}: {err}"
            );
        }
    }
    assert!(!png.exists());
    // Build options are named, and refused before the input is read.
    for (args, message) in [
        (vec!["--cluster-size", "1"], "--cluster-size 1"),
        (vec!["--delta-n", "0"], "--delta-n 0"),
        (
            vec!["--root-points", "4"],
            "--root-points 4 is below --cluster-size 8",
        ),
    ] {
        let mut all = vec!["convert", "missing.lammpstrj", "-o", "out.mdlod"];
        all.extend(args);
        let err = fails(&all);
        assert!(err.contains(message), "{err}");
    }
    // A rejected particle count leaves an existing output alone.
    let existing = dir.path().join("existing.lammpstrj");
    std::fs::write(&existing, "keep me").unwrap();
    let err = fails(&["generate", "crater", "-n", "0", "-o", s(&existing)]);
    assert!(err.contains("--particles 0"), "{err}");
    assert_eq!(std::fs::read_to_string(&existing).unwrap(), "keep me");
    // A script timeout past the clock's range means no deadline, not a panic.
    let script = dir.path().join("s.json");
    std::fs::write(&script, "[]").unwrap();
    let err = fails(&[
        "view",
        s(&dir.path().join("missing.mdlod")),
        "--script",
        s(&script),
        "--script-timeout",
        "18446744073709551615",
    ]);
    assert!(err.contains("missing.mdlod"), "{err}");
}

#[test]
fn cameras_too_far_from_the_data_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let frame = converted(dir.path(), "cu_melt.custom.dump");
    let png = dir.path().join("x.png");
    let err = fails(&["render", s(&frame), "-o", s(&png), "--zoom", "1e-38"]);
    assert!(
        err.contains("zoom 1e-38") && err.contains("too far"),
        "{err}"
    );
    let view = dir.path().join("far.json");
    std::fs::write(&view, r#"{"version": 1, "distance": 1e38}"#).unwrap();
    let err = fails(&["render", s(&frame), "-o", s(&png), "--view", s(&view)]);
    assert!(err.contains("far.json") && err.contains("too far"), "{err}");
    assert!(!png.exists());
}

#[test]
fn negative_numbers_mode_aliases_and_levels_get_the_programs_own_answers() {
    let dir = tempfile::tempdir().unwrap();
    let frame = converted(dir.path(), "cu_melt.custom.dump");
    let png = dir.path().join("x.png");
    let (f, p) = (s(&frame), s(&png));
    // A negative number is a value, answered by the range check, not a clap tip to
    // write `-- -1`.
    for (args, message) in [
        (vec!["render", f, "-o", p, "--zoom", "-1"], "zoom"),
        (
            vec!["render", f, "-o", p, "--screen-error", "-1"],
            "a finite number, 0 or more",
        ),
        (
            vec!["sample", f, "-o", p, "--screen-error", "-1"],
            "a finite number, 0 or more",
        ),
        (vec!["view", f, "--width", "-1"], "--width"),
    ] {
        let err = fails(&args);
        assert!(
            err.contains(message) && !err.contains("unexpected argument"),
            "{args:?}: {err}"
        );
    }
    // Each command's name of the sphere mode is the other's alias (a size check that
    // needs no GPU answers render; the missing file answers view).
    let err = fails(&[
        "render", f, "-o", p, "--mode", "standard", "--width", "40000",
    ]);
    assert!(err.contains("must each be 1 to 32768"), "{err}");
    let missing = dir.path().join("missing.mdlod");
    let err = fails(&["view", s(&missing), "--mode", "spheres"]);
    assert!(err.contains("missing.mdlod"), "{err}");
    let script = dir.path().join("s.json");
    std::fs::write(&script, r#"[{"action": "mode", "mode": "spheres"}]"#).unwrap();
    let err = fails(&["view", s(&missing), "--script", s(&script)]);
    assert!(
        err.contains("missing.mdlod") && !err.contains("variant"),
        "{err}"
    );
    // Levels print as numbers.
    let sndf = dir.path().join("v.sndf");
    std::fs::write(&sndf, "x").unwrap();
    let err = fails(&["shade", s(&sndf), "-o", p, "--level", "17"]);
    assert!(err.contains("--level 17 (at most 16)"), "{err}");
    assert!(!png.exists());
    // Help names every render mode and describes the positional file.
    let help = ok(&["--help"]);
    let render = help
        .lines()
        .find(|l| l.trim_start().starts_with("render"))
        .unwrap();
    assert!(
        render.contains("splats") && render.contains("iso-surface"),
        "{help}"
    );
    let help = ok(&["render", "--help"]);
    assert!(help.contains("The .mdlod file to render"), "{help}");
    // sample shares render's style options; its help speaks only of what it has.
    let help = ok(&["sample", "--help"]);
    for absent in ["--intensity", "movie", "density and iso"] {
        assert!(!help.contains(absent), "{absent}: {help}");
    }
    assert!(help.contains("views sampled apart compare"), "{help}");
    let help = ok(&["shade", "--help"]);
    assert!(help.contains("The .sndf file to shade"), "{help}");
}

/// `info` gives the extent of the particles' spheres (the box a fitted view frames),
/// which a simulation box need not match.
#[test]
fn info_gives_the_extent_of_the_particles() {
    let dir = tempfile::tempdir().unwrap();
    let xyz = dir.path().join("two.xyz");
    std::fs::write(&xyz, "2\nplain\nCu 0 0 0\nCu 10 2 -3\n").unwrap();
    let file = dir.path().join("two.mdlod");
    ok(&["convert", s(&xyz), "-o", s(&file), "--radius", "Cu=1"]);
    let text = ok(&["info", s(&file)]);
    assert!(
        text.contains(
            "extent       [-1.0, -1.0, -4.0] to [11.0, 3.0, 1.0] (the particles' spheres)"
        ),
        "{text}"
    );
    let json: serde_json::Value = serde_json::from_str(&ok(&["info", s(&file), "--json"])).unwrap();
    assert_eq!(json["extent"]["min"], serde_json::json!([-1.0, -1.0, -4.0]));
    assert_eq!(json["extent"]["max"], serde_json::json!([11.0, 3.0, 1.0]));
    // The colour is printed linear, as stored, with the sRGB #rrggbb that
    // --species-colour takes beside it: the one back to the other within a step.
    let line = text.lines().find(|l| l.contains("species ")).unwrap();
    let hex = line.split("linear, #").nth(1).unwrap();
    let stored = json["species"][0]["colour"].as_array().unwrap();
    for k in 0..3 {
        let v = u8::from_str_radix(&hex[2 * k..2 * k + 2], 16).unwrap();
        let linear = mdlod_render::renderer::srgb_to_linear(f32::from(v) / 255.0);
        let want = stored[k].as_f64().unwrap() as f32;
        assert!((linear - want).abs() < 0.01, "{line}: channel {k}");
    }
    // Six significant digits, in scientific notation where large or small.
    std::fs::write(&xyz, "2\nplain\nCu 3.72 4.72 -3.28\nCu 1e20 2e-10 0\n").unwrap();
    ok(&["convert", s(&xyz), "-o", s(&file), "--radius", "Cu=1"]);
    let text = ok(&["info", s(&file)]);
    assert!(
        text.contains("[2.72, -1.0, -4.28] to [1e20, 5.72, 1.0]"),
        "{text}"
    );
}

#[test]
fn info_prints_boxes_without_rounding_noise() {
    let dir = tempfile::tempdir().unwrap();
    // LAMMPS writes this box as 1.8075000000000003e+01.
    let frame = dir.path().join("a.mdlod");
    let input = lammps_sample_path("cu_melt.custom.dump");
    ok(&["convert", s(&input), "-o", s(&frame), "--radius", "1=1.28"]);
    let text = ok(&["info", s(&frame)]);
    assert!(
        text.contains("a [18.075, 0.0, 0.0]") && !text.contains("00000"),
        "{text}"
    );
    let json = ok(&["info", s(&frame), "--json"]);
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    // Radii are f32s: their shortest form, not their f64 widening.
    assert_eq!(v["species"][0]["radius"].to_string(), "1.28", "{json}");
}

#[test]
fn render_and_sample_summaries_name_the_limit_that_applied() {
    let dir = tempfile::tempdir().unwrap();
    let frame = converted(dir.path(), "cu_melt.custom.dump");
    let png = dir.path().join("x.png");
    let (f, p) = (s(&frame), s(&png));
    let small = ["--width", "48", "--height", "32"];
    let text = ok(&[&["render", f, "-o", p, "--budget", "10"][..], &small].concat());
    assert!(
        text.contains("point budget of 10: below the") && !text.contains("memory pool"),
        "{text}"
    );
    // A pool that holds the coarse levels (the least that is accepted) and little more:
    // 20 000 particles, at most 4096 on the coarsest level (57 KiB).
    let dump = dir.path().join("c.lammpstrj");
    generate(&["crater", "-n", "20000"], &dump);
    let larger = dir.path().join("c.mdlod");
    ok(&["convert", s(&dump), "-o", s(&larger)]);
    let text = ok(&[
        &[
            "render",
            s(&larger),
            "-o",
            p,
            "--gpu-memory",
            "64K",
            "--budget",
            "100000000",
        ][..],
        &small,
    ]
    .concat());
    assert!(
        text.contains("GPU memory pool full: a larger --gpu-memory")
            && !text.contains("point budget"),
        "{text}"
    );
    let text = ok(&[
        &["render", f, "-o", p, "--mode", "sndf", "--iterations", "2"][..],
        &small,
    ]
    .concat());
    assert!(
        text.contains("2 rays per pixel") && !text.contains("spp"),
        "{text}"
    );
    // More tiles than one buffer holds: the advice names sample's options, not the
    // viewer's pool and window.
    let sndf = dir.path().join("t.sndf");
    let err = fails(&[
        "sample",
        f,
        "-o",
        s(&sndf),
        "--tiles",
        "--ortho",
        "--bins",
        "32",
        "--width",
        "4096",
        "--height",
        "4096",
    ]);
    assert!(
        err.contains("--bins")
            && err.contains("--width")
            && !err.contains("window")
            && !err.contains("render options"),
        "{err}"
    );
    assert!(!sndf.exists());
}

/// The `frame-*.mdlod` files of a batch directory (none when it does not exist).
fn batch_frames(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .map(|d| {
            d.flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.starts_with("frame-") && n.ends_with(".mdlod"))
                .collect()
        })
        .unwrap_or_default();
    names.sort();
    names
}

/// A radius override that no frame can hold (an element symbol where the species are
/// LAMMPS type numbers, a type number where they come from an `element` column) is
/// refused before any frame is converted, in every shard, saying what to write instead;
/// a name that may occur in some frame only is checked at the end, as before.
#[test]
fn batch_refuses_a_radius_no_frame_can_hold_before_converting_anything() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("a.lammpstrj");
    generate(&["alloy", "-n", "2000", "--frames", "3"], &input);
    let d = dir.path().join("d");
    for shard in [None, Some("0/2"), Some("1/2")] {
        let mut args = vec!["batch", s(&input), "-o", s(&d), "--radius", "Cu=1.28"];
        if let Some(sh) = shard {
            args.extend(["--shard", sh]);
        }
        let err = fails(&args);
        assert!(
            err.contains(s(&input))
                && err.contains("--radius Cu=1.28")
                && err.contains("no species named \"Cu\"")
                && err.contains("LAMMPS type number")
                && err.contains("--radius 1=1.28 for type 1"),
            "{shard:?}: {err}"
        );
        assert_eq!(batch_frames(&d), Vec::<String>::new(), "{shard:?}");
    }
    // A number that names no frame's species may belong to a later frame: checked at
    // the end, listing the species, and saying that the frames converted stay; with
    // --json, how many.
    let err = fails(&["batch", s(&input), "-o", s(&d), "--radius", "3=1"]);
    assert!(
        err.contains("no species named \"3\"")
            && err.contains("the input's species are named 1, 2")
            && !err.contains("the input has")
            && err.contains(
                "the frames converted (3) and already done (0) are complete and listed in \
                 the manifest"
            ),
        "{err}"
    );
    assert_eq!(batch_frames(&d).len(), 3);
    let out = mdlod(&["batch", s(&input), "-o", s(&d), "--radius", "3=1", "--json"]);
    assert!(!out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        (&v["ok"], &v["converted"], &v["already_done"]),
        (&false.into(), &0.into(), &3.into()),
        "{v}"
    );
    ok(&[
        "batch",
        s(&input),
        "-o",
        s(&d),
        "--radius",
        "1=1.28",
        "--radius",
        "2=1.44",
    ]);
    assert_eq!(batch_frames(&d).len(), 3);

    // Species named by an `element` column: a type number names none of them.
    let alloy = lammps_sample_path("cuag_alloy.unwrapped.dump");
    let e = dir.path().join("e");
    let err = fails(&["batch", s(&alloy), "-o", s(&e), "--radius", "1=1.3"]);
    assert!(
        err.contains(s(&alloy))
            && err.contains("--radius 1=1.3")
            && err.contains("`element` column")
            && err.contains("--radius Cu=1.3 (type 1 is Cu)"),
        "{err}"
    );
    assert_eq!(batch_frames(&e), Vec::<String>::new());
    let out = dir.path().join("e.mdlod");
    let err = fails(&["convert", s(&alloy), "-o", s(&out), "--radius", "1=1.3"]);
    assert!(
        err.contains(s(&alloy))
            && err.contains("--radius 1=1.3")
            && err.contains("the input's species are named Cu, Ag")
            && err.contains("`element` column")
            && err.contains("--radius Cu=1.3"),
        "{err}"
    );
    assert!(!out.exists());
    ok(&["convert", s(&alloy), "-o", s(&out), "--radius", "Cu=1.3"]);
    // And `convert` on type numbers says what to write too.
    let err = fails(&["convert", s(&input), "-o", s(&out), "--radius", "Ag=1.44"]);
    assert!(
        err.contains(s(&input))
            && err.contains("the input's species are named 1, 2")
            && err.contains("--radius 1=1.44 for type 1"),
        "{err}"
    );
}

/// The attribute of every frame of a batch directory (`None`: none).
fn batch_attributes(dir: &Path) -> Vec<Option<String>> {
    batch_frames(dir)
        .iter()
        .map(|f| {
            MdlodFile::open(dir.join(f))
                .unwrap()
                .metadata()
                .attribute
                .as_ref()
                .map(|a| a.name.clone())
        })
        .collect()
}

/// A rerun asking for another attribute, or none, or one where there was none, converts
/// the frames again; a column the input lacks is an error naming it and the file.
#[test]
fn a_batch_rerun_with_another_attribute_converts_the_frames_again() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("a.lammpstrj");
    generate(&["alloy", "-n", "2000", "--frames", "3"], &input);
    let d = dir.path().join("d");
    let run = |attribute: Option<&str>| {
        let mut args = vec!["batch", s(&input), "-o", s(&d)];
        if let Some(a) = attribute {
            args.extend(["--attribute", a]);
        }
        ok(&args)
    };
    let some = |a: &str| vec![Some(a.to_string()); 3];
    assert!(run(Some("c_pe")).contains("3 converted, 0 already done"));
    assert_eq!(batch_attributes(&d), some("c_pe"));
    assert!(run(Some("c_pe")).contains("0 converted, 3 already done"));
    assert!(run(Some("x")).contains("3 converted, 0 already done"));
    assert_eq!(batch_attributes(&d), some("x"));
    assert!(run(None).contains("3 converted, 0 already done"));
    assert_eq!(batch_attributes(&d), vec![None; 3]);
    assert!(run(None).contains("0 converted, 3 already done"));
    assert!(run(Some("c_pe")).contains("3 converted, 0 already done"));
    assert_eq!(batch_attributes(&d), some("c_pe"));
    let err = fails(&["batch", s(&input), "-o", s(&d), "--attribute", "nosuch"]);
    assert!(
        err.contains(s(&input)) && err.contains("`nosuch`") && err.contains("c_pe"),
        "{err}"
    );
    // Nothing was touched.
    assert_eq!(batch_attributes(&d), some("c_pe"));

    // A gzip input (its text is dropped after indexing) and a binary dump alike.
    for (sample, first, other) in [
        ("cu_melt.custom.dump.gz", "c_ke", "vx"),
        ("cu_melt.custom.bin", "c_pe", "x"),
    ] {
        let input = lammps_sample_path(sample);
        let d = dir.path().join(sample);
        let run = |a: &str| ok(&["batch", s(&input), "-o", s(&d), "--attribute", a]);
        let n = batch_frames(&d).len();
        assert!(run(first).contains(", 0 already done"), "{sample}");
        let frames = batch_frames(&d).len();
        assert!(frames > n);
        assert!(
            run(first).contains(&format!("0 converted, {frames} already done")),
            "{sample}"
        );
        assert!(
            run(other).contains(&format!("{frames} converted, 0 already done")),
            "{sample}"
        );
        assert_eq!(batch_attributes(&d), vec![Some(other.to_string()); frames]);
        let err = fails(&["batch", s(&input), "-o", s(&d), "--attribute", "nosuch"]);
        assert!(err.contains(sample) && err.contains("`nosuch`"), "{err}");
    }
}

/// The same data as extended XYZ and as a LAMMPS dump lists its species in the same
/// order (numeric names numerically), so the colours do not swap with the format.
#[test]
fn xyz_and_lammps_forms_of_the_same_data_get_the_same_species_table() {
    let dir = tempfile::tempdir().unwrap();
    let mut tables = vec![];
    for (name, format) in [("d.xyz", "xyz"), ("d.lammpstrj", "lammps")] {
        let input = dir.path().join(name);
        ok(&[
            "generate",
            "droplets",
            "-n",
            "20000",
            "--format",
            format,
            "-o",
            s(&input),
        ]);
        for chunk_points in [None, Some("4096")] {
            let out = dir.path().join(format!("{name}.mdlod"));
            let mut args = vec!["convert", s(&input), "-o", s(&out)];
            if let Some(c) = chunk_points {
                args.extend(["--chunk-points", c]);
            }
            ok(&args);
            let file = MdlodFile::open(&out).unwrap();
            let species: Vec<(String, [u32; 3])> = file
                .metadata()
                .species
                .iter()
                .map(|s| (s.name.clone(), s.colour.map(f32::to_bits)))
                .collect();
            tables.push((name, chunk_points, species));
        }
    }
    let names: Vec<&str> = tables[0].2.iter().map(|s| s.0.as_str()).collect();
    assert_eq!(names, ["1", "2"]);
    for t in &tables[1..] {
        assert_eq!(t.2, tables[0].2, "{:?} vs {:?}", t, tables[0]);
    }
}

#[test]
fn a_closed_output_pipe_drops_the_output_and_the_work_completes() {
    // `mdlod info frame.mdlod | head -1`: the reader is gone before the program writes.
    // std's println! panicked there ("failed printing to stdout: Broken pipe"), and
    // `render --save-view` printed its summary before saving the view, so the view file
    // was never written.
    let dir = tempfile::tempdir().unwrap();
    let frame = converted(dir.path(), "cu_melt.custom.dump");
    let view = dir.path().join("v.json");
    let png = dir.path().join("x.png");
    for args in [
        vec!["info", s(&frame)],
        vec![
            "render",
            s(&frame),
            "-o",
            s(&png),
            "--width",
            "64",
            "--height",
            "48",
            "--save-view",
            s(&view),
        ],
    ] {
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let out = Command::new(env!("CARGO_BIN_EXE_mdlod"))
            .args(&args)
            .stdout(writer)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!err.contains("panicked"), "{args:?}: {err}");
        assert!(out.status.success(), "{args:?}: {:?}: {err}", out.status);
    }
    assert!(png.is_file() && view.is_file());
}
/// Ten spheres of radius 0.1 spread over 90 units, each narrower than a pixel, with a
/// constant attribute (equal masses), as a LAMMPS dump converted.
fn sparse_equal_masses(dir: &Path) -> PathBuf {
    let dump = dir.join("sparse.lammpstrj");
    let mut text = String::from(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n10\nITEM: BOX BOUNDS pp pp pp\n\
         -1 91\n-1 1\n-1 1\nITEM: ATOMS id type x y z mass\n",
    );
    for i in 0..10 {
        text.push_str(&format!("{} 1 {} 0 0 2.5e-6\n", i + 1, 10 * i));
    }
    std::fs::write(&dump, text).unwrap();
    let out = dir.join("sparse.mdlod");
    ok(&[
        "convert",
        s(&dump),
        "-o",
        s(&out),
        "--radius",
        "1=0.1",
        "--attribute",
        "mass",
    ]);
    out
}

/// Spheres that fall between pixel centres are left out like hidden ones (nothing would
/// show them), and the summary says so rather than calling them hidden; splats lit by a
/// constant attribute show every point (they were black: the constant mapped to 0).
#[test]
fn render_says_what_it_left_out_and_lights_a_constant_attribute() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let file = sparse_equal_masses(d);
    let png = d.join("x.png");
    let size = ["--width", "400", "--height", "200"];
    // Seen from straight above, the line of spheres (0.8 px wide) lies on the boundary
    // between two rows of pixel centres.
    let mut args = vec!["render", s(&file), "-o", s(&png), "--elevation", "90"];
    args.extend(size);
    let out = ok(&args);
    assert!(
        out.contains("10 particles left out behind nearer spheres or between pixel centres"),
        "{out}"
    );
    // Nothing drawn: said as what it is, not as data out of view.
    assert!(
        out.contains("nothing is drawn: every sphere in view is narrower than the pixels"),
        "{out}"
    );
    assert!(!out.contains("hidden particles"), "{out}");
    let mut args = vec!["render", s(&file), "-o", s(&png), "--mode", "splat"];
    args.extend(size);
    args.extend(["--intensity", "attribute", "--screen-error", "0"]);
    ok(&args);
    let (_, _, img) = read_png(&png);
    let lit = img
        .chunks_exact(4)
        .filter(|p| p[0] > 100 && p[0] == p[1] && p[1] == p[2])
        .count();
    assert!(lit >= 10, "{lit} lit pixels");
}

/// A budget of 0 spheres is refused (it was taken as 1 and reported as "a point budget
/// of 1"); a negative absorption is reported under its option's name (it said
/// "opacity").
#[test]
fn render_refuses_a_zero_budget_and_names_the_absorption() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let file = sparse_equal_masses(d);
    let png = d.join("x.png");
    let err = fails(&["render", s(&file), "-o", s(&png), "--budget", "0"]);
    assert!(
        err.contains("--budget") && err.contains("at least 1"),
        "{err}"
    );
    let err = fails(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--mode",
        "density",
        "--absorption",
        "-1",
    ]);
    assert!(
        err.contains("--absorption -1") && !err.contains("opacity"),
        "{err}"
    );
    assert!(!png.exists());
    // A budget of 1 draws the whole data set as one sphere.
    let out = ok(&["render", s(&file), "-o", s(&png), "--budget", "1"]);
    assert!(
        out.contains("point budget of 1: below the")
            && out.contains("points the top node opens into (level 1")
            && out.contains("is one sphere"),
        "{out}"
    );
}

/// A batch skips a frame without particles (it cannot be a `.mdlod` file), saying which
/// frame of which input and why, counts it in its summary, and does the same on a rerun
/// (it failed the whole batch, on every rerun, without naming the frame); `convert` of
/// such a frame stays an error, naming the frame and its timestep.
#[test]
fn batch_skips_an_empty_frame_saying_which_and_convert_names_it() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("thresh.dump");
    let mut text = String::new();
    for (step, n) in [(0, 3), (100, 0), (200, 2)] {
        text.push_str(&format!(
            "ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ATOMS\n{n}\nITEM: BOX BOUNDS pp pp pp\n\
             0 10\n0 10\n0 10\nITEM: ATOMS id type x y z\n"
        ));
        for i in 0..n {
            text.push_str(&format!("{} 1 {i} {i} {i}\n", i + 1));
        }
    }
    std::fs::write(&input, text).unwrap();
    let d = dir.path().join("d");
    let skipped = format!(
        "{}: frame 1 (timestep 100) has no particles: skipped, as a .mdlod file needs at \
         least one (not written; listed as empty in the manifest)\n",
        s(&input)
    );
    let out = ok(&["batch", s(&input), "-o", s(&d)]);
    assert!(out.starts_with(&skipped), "{out}");
    assert!(
        out.contains("3 frames in the inputs: 2 converted, 0 already done, 1 empty frame skipped;"),
        "{out}"
    );
    assert_eq!(batch_frames(&d), ["frame-0.mdlod", "frame-200.mdlod"]);
    // `info` of the directory names it, in text and JSON.
    let info = ok(&["info", s(&d)]);
    assert!(
        info.contains(
            "empty        1 frame without particles, not converted (a .mdlod file needs one): \
             timestep 100"
        ),
        "{info}"
    );
    let v: serde_json::Value = serde_json::from_str(&ok(&["info", s(&d), "--json"])).unwrap();
    assert_eq!(v["empty"][0]["timestep"], 100, "{v}");
    let again = ok(&["batch", s(&input), "-o", s(&d)]);
    assert!(again.starts_with(&skipped), "{again}");
    assert!(
        again.contains(": 0 converted, 2 already done, 1 empty frame skipped;"),
        "{again}"
    );
    let frame = dir.path().join("f.mdlod");
    let err = fails(&["convert", s(&input), "-o", s(&frame), "--frame", "1"]);
    assert!(
        err.contains(&format!(
            "{}: frame 1 (timestep 100): no particles, and a .mdlod file needs at least one",
            s(&input)
        )),
        "{err}"
    );
    assert!(!frame.exists());
}

/// A process that has ended: `true`, waited for.
fn dead_pid() -> u32 {
    let mut child = Command::new("true").spawn().unwrap();
    child.wait().unwrap();
    child.id()
}

#[test]
fn leftovers_of_killed_runs_on_this_host_are_removed_and_named_by_the_next_run() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("alloy.lammpstrj");
    generate(&["alloy", "-n", "3000", "--frames", "2"], &input);
    let host = mdlod_format::writer::host_name();
    let dead = dead_pid();
    // Killed but not yet reaped by its parent: only its zombie is left in /proc.
    let mut zombie = Command::new("sleep").arg("60").spawn().unwrap();
    zombie.kill().unwrap();
    let mut live = Command::new("sleep").arg("60").spawn().unwrap();
    let (zombie_pid, live_pid) = (zombie.id(), live.id());
    let work_dir = |parent: &Path, name: String, bytes: usize| {
        let d = parent.join(name);
        std::fs::create_dir_all(&d).unwrap();
        std::fs::write(d.join("cell-000.cell"), vec![0u8; bytes]).unwrap();
        d
    };
    let file = |parent: &Path, name: String| {
        let f = parent.join(name);
        std::fs::write(&f, b"partial").unwrap();
        f
    };

    // A batch directory.
    let out = dir.path().join("d");
    std::fs::create_dir(&out).unwrap();
    let removed = [
        work_dir(
            &out,
            format!(".mdlod-convert-{host}-{dead}-abc123"),
            2_000_000,
        ),
        work_dir(
            &out,
            format!(".mdlod-convert-{host}-{zombie_pid}-zzz123"),
            10,
        ),
        file(&out, format!(".frame-900.mdlod.{host}-{dead}-abc123.tmp")),
        // A manifest being written when its run was killed.
        file(&out, format!(".dataset.{host}-{dead}-abc123.tmp")),
    ];
    let kept = [
        work_dir(&out, format!(".mdlod-convert-{host}-{live_pid}-liv123"), 10),
        work_dir(&out, format!(".mdlod-convert-x{host}-{dead}-abc123"), 10),
        work_dir(&out, format!(".mdlod-convert-{host}-abc123"), 10),
        file(
            &out,
            format!(".frame-900.mdlod.{host}-{live_pid}-abc123.tmp"),
        ),
        file(&out, ".frame-900.mdlod.abc123.tmp".into()),
        file(&out, format!(".frame-900.mdlod.x{host}-{dead}-abc123.tmp")),
        file(&out, format!(".dataset.{host}-{live_pid}-abc123.tmp")),
    ];
    let said = ok(&["batch", s(&input), "-o", s(&out)]);
    assert!(
        said.contains(&format!(
            "removed working files of an interrupted run: {} (2.0 MB)",
            removed[0].display()
        )),
        "{said}"
    );
    for p in &removed {
        assert!(!p.exists(), "{} left: {said}", p.display());
        assert!(said.contains(&p.display().to_string()), "{said}");
    }
    for p in &kept {
        assert!(p.exists(), "{} removed", p.display());
    }

    // A conversion with --temp-dir: working directories there and in the output's
    // directory, and outputs' temporary files.
    let temp = dir.path().join("temp");
    std::fs::create_dir(&temp).unwrap();
    let output = dir.path().join("out.mdlod");
    let removed = [
        work_dir(&temp, format!(".mdlod-convert-{host}-{dead}-abc123"), 10),
        work_dir(
            dir.path(),
            format!(".mdlod-convert-{host}-{dead}-def456"),
            10,
        ),
        file(dir.path(), format!(".out.mdlod.{host}-{dead}-abc123.tmp")),
        // Another output's, whose conversion may never run again.
        file(dir.path(), format!(".other.mdlod.{host}-{dead}-abc123.tmp")),
    ];
    let kept = [
        file(
            dir.path(),
            format!(".out.mdlod.{host}-{live_pid}-abc123.tmp"),
        ),
        file(dir.path(), ".out.mdlod.abc123.tmp".into()),
    ];
    let said = ok(&[
        "convert",
        s(&input),
        "-o",
        s(&output),
        "--temp-dir",
        s(&temp),
    ]);
    for p in &removed {
        assert!(!p.exists(), "{} left: {said}", p.display());
        assert!(said.contains(&p.display().to_string()), "{said}");
    }
    for p in &kept {
        assert!(p.exists(), "{} removed", p.display());
    }
    ok(&["verify", s(&output)]);
    live.kill().unwrap();
    live.wait().unwrap();
    zombie.wait().unwrap();
}

#[test]
fn sigterm_cleans_up_as_ctrl_c_does() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("alloy.raw.json");
    generate(&["alloy", "-n", "120000", "--format", "raw"], &input);
    let out = dir.path().join("terminated.mdlod");
    let child = convert_until_chunks_are_built(dir.path(), &input, &out);
    let status = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let done = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&done.stderr);
    assert_eq!(done.status.code(), Some(130), "{err}");
    assert!(err.contains("interrupted: working files removed"), "{err}");
    assert!(!out.exists());
    assert!(
        working_entries(dir.path()).is_empty(),
        "{:?}",
        working_entries(dir.path())
    );
}

#[test]
fn viewing_a_batch_whose_shards_are_not_merged_says_to_merge_them() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("dataset.shard-0-of-2.json"), b"{}").unwrap();
    let err = fails(&["view", s(dir.path())]);
    assert!(
        err.contains(&format!("mdlod batch --merge {}", dir.path().display()))
            && err.contains("dataset.shard-0-of-2.json"),
        "{err}"
    );
}

/// The text of the LAMMPS dump `path` with every atom line's fields changed by `edit`
/// (given the frame's index, from 0).
fn edit_atoms(path: &Path, mut edit: impl FnMut(usize, &mut Vec<String>)) -> String {
    let mut out = String::new();
    let (mut frame, mut atoms) = (None::<usize>, false);
    for line in std::fs::read_to_string(path).unwrap().lines() {
        if line.starts_with("ITEM:") {
            if line.starts_with("ITEM: TIMESTEP") {
                frame = Some(frame.map_or(0, |k| k + 1));
            }
            atoms = line.starts_with("ITEM: ATOMS");
            out.push_str(line);
        } else if atoms {
            let mut fields: Vec<String> = line.split_whitespace().map(String::from).collect();
            edit(frame.unwrap_or(0), &mut fields);
            out.push_str(&fields.join(" "));
        } else {
            out.push_str(line);
        }
        out.push('\n');
    }
    out
}

/// A movie colours every frame over one attribute range: two frames whose values differ
/// tenfold render alike with each file's own range, and differently over `--attribute-range`
/// (as colours and as splat intensities). Splats lit by the attribute carry it in its own
/// units: with each file's range (from its smallest value) the tenfold frame has ten
/// times the light. The option needs something that reads the attribute.
#[test]
fn an_attribute_range_colours_every_frame_alike() {
    let dir = tempfile::tempdir().unwrap();
    let cold = dir.path().join("cold.lammpstrj");
    generate(&["alloy", "-n", "4000"], &cold);
    let hot_path = dir.path().join("hot.lammpstrj");
    let hot = edit_atoms(&cold, |_, f| {
        let v: f64 = f[5].parse().unwrap();
        f[5] = (v * 10.0).to_string();
    });
    std::fs::write(&hot_path, hot).unwrap();
    let render = |input: &Path, extra: &[&str]| -> Vec<u8> {
        let file = input.with_extension("mdlod");
        if !file.exists() {
            ok(&["convert", s(input), "-o", s(&file), "--attribute", "c_pe"]);
        }
        let png = dir.path().join("out.png");
        let mut args = vec![
            "render",
            s(&file),
            "-o",
            s(&png),
            "--width",
            "64",
            "--height",
            "48",
        ];
        args.extend(extra);
        ok(&args);
        read_png(&png).2
    };
    // The largest difference of one channel between two images of one size.
    let largest = |a: &[u8], b: &[u8]| {
        assert_eq!(a.len(), b.len());
        a.iter()
            .zip(b)
            .map(|(x, y)| x.abs_diff(*y))
            .max()
            .unwrap_or(0)
    };
    for mode in [
        &["--colour-map", "viridis"][..],
        &[
            "--mode",
            "splat",
            "--intensity",
            "attribute",
            "--exposure",
            "0.5",
        ][..],
    ] {
        if mode[0] == "--mode" {
            let flux = |input: &Path| -> f64 {
                let file = input.with_extension("mdlod");
                let png = dir.path().join("out.png");
                let mut args = vec!["render", s(&file), "-o", s(&png)];
                args.extend(["--width", "64", "--height", "48"]);
                args.extend(mode);
                let out = ok(&args);
                let at = out.find("total flux ").expect("a total flux") + "total flux ".len();
                out[at..]
                    .split_whitespace()
                    .next()
                    .unwrap()
                    .parse()
                    .unwrap()
            };
            render(&cold, mode);
            render(&hot_path, mode);
            let ratio = flux(&hot_path) / flux(&cold);
            assert!((ratio - 10.0).abs() < 1e-3, "{ratio}");
        } else {
            // Alike to the rounding of the last bit (each file quantizes its own range).
            let (a, b) = (render(&cold, mode), render(&hot_path, mode));
            assert!(largest(&a, &b) <= 1, "{mode:?}: {}", largest(&a, &b));
        }
        let ranged: Vec<&str> = mode
            .iter()
            .copied()
            .chain(["--attribute-range", "-40:0"])
            .collect();
        let (a, b) = (render(&cold, &ranged), render(&hot_path, &ranged));
        assert!(largest(&a, &b) > 16, "{mode:?}: {}", largest(&a, &b));
    }
    let file = cold.with_extension("mdlod");
    let png = dir.path().join("x.png");
    // The summary says what the colours mean.
    let small = ["--width", "16", "--height", "12", "--colour-map", "viridis"];
    let out = ok(&[&["render", s(&file), "-o", s(&png)][..], &small].concat());
    assert!(
        out.contains("colour map viridis: c_pe from ") && out.contains("(the file's range)"),
        "{out}"
    );
    let out = ok(&[
        &["render", s(&file), "-o", s(&png)][..],
        &small,
        &["--attribute-range", "-40:0"],
    ]
    .concat());
    assert!(
        out.contains("colour map viridis: c_pe from -40 to 0 (--attribute-range)"),
        "{out}"
    );
    let err = fails(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--attribute-range",
        "0:1",
    ]);
    assert!(err.contains("no effect without --colour-map"), "{err}");
    let err = fails(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--colour-map",
        "grey",
        "--attribute-range",
        "2:1",
    ]);
    assert!(err.contains("MAX must be above MIN"), "{err}");
}

/// A batch directory renders as a movie: one image per frame in time order, all with
/// the camera fitted to every frame's bounds and, coloured by the attribute, over the
/// union of the frames' ranges; a frame rendered alone with the saved view and that range
/// is the same image. The output must number the frames.
#[test]
fn a_batch_directory_renders_every_frame_with_one_camera() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("t.lammpstrj");
    generate(&["droplets", "-n", "3000", "--frames", "3"], &dump);
    let d = dir.path().join("t.d");
    ok(&["batch", s(&dump), "-o", s(&d), "--attribute", "v_temp"]);
    let manifest = mdlod_preprocess::batch::read_manifest(&d).unwrap();
    let ranges: Vec<[f32; 2]> = manifest
        .frames
        .iter()
        .map(|f| {
            let file = mdlod_format::MdlodFile::open(d.join(&f.file)).unwrap();
            let a = file.metadata().attribute.clone().expect("an attribute");
            [a.min, a.max]
        })
        .collect();
    let lo = ranges.iter().map(|r| r[0]).fold(f32::INFINITY, f32::min);
    let hi = ranges
        .iter()
        .map(|r| r[1])
        .fold(f32::NEG_INFINITY, f32::max);
    assert!(ranges.iter().any(|r| *r != [lo, hi]), "{ranges:?}");
    let pattern = dir.path().join("movie").join("f-%03d.png");
    let view = dir.path().join("v.json");
    let size = ["--width", "48", "--height", "32", "--colour-map", "viridis"];
    let mut args = vec!["render", s(&d), "-o", s(&pattern), "--save-view", s(&view)];
    args.extend(size);
    let out = ok(&args);
    assert!(out.contains("rendered 3 frames"), "{out}");
    assert!(out.contains(&format!("from {lo} to {hi}")), "{out}");
    let range = format!("{lo}:{hi}");
    for (i, f) in manifest.frames.iter().enumerate() {
        let image = dir.path().join("movie").join(format!("f-{i:03}.png"));
        assert!(out.contains(&format!("timestep {}", f.timestep)), "{out}");
        let alone = dir.path().join("alone.png");
        let file = d.join(&f.file);
        let mut args = vec!["render", s(&file), "-o", s(&alone), "--view", s(&view)];
        args.extend(size);
        args.extend(["--attribute-range", &range]);
        ok(&args);
        assert_eq!(
            std::fs::read(&image).unwrap(),
            std::fs::read(&alone).unwrap(),
            "{i}"
        );
    }
    let err = fails(&["render", s(&d), "-o", s(&dir.path().join("one.png"))]);
    assert!(err.contains("one image per frame"), "{err}");
    // Each frame's line says why its cut stopped, as a single image's does.
    let mut args = vec!["render", s(&d), "-o", s(&pattern), "--budget", "1"];
    args.extend(size);
    let out = ok(&args);
    assert_eq!(out.matches("is one sphere").count(), 3, "{out}");
    assert!(out.contains("3 coarsened by the point budget"), "{out}");
}

/// Two names no frame holds together (a solvent that evaporates, ions deposited where it
/// was) take the same palette slot in their own frames' files: a movie and its legend
/// still tell them apart. Here the second frame's ions stand where the first frame's
/// solvent stood: its image must differ, and the legend's two swatches too.
#[test]
fn a_movie_tells_apart_species_that_never_share_a_frame() {
    let dir = tempfile::tempdir().unwrap();
    let frame = |other: &str| {
        let mut t = format!("{}\nframe\n", 2 * 64);
        for i in 0..64 {
            let p = [
                (i % 4) as f32 * 2.0,
                (i / 4 % 4) as f32 * 2.0,
                (i / 16) as f32 * 2.0,
            ];
            t += &format!("LIP {} {} {}\n", p[0], p[1], p[2]);
            t += &format!("{other} {} {} {}\n", p[0] + 10.0, p[1], p[2]);
        }
        t
    };
    let xyz = dir.path().join("depo.xyz");
    std::fs::write(&xyz, frame("SOL") + &frame("ION")).unwrap();
    let d = dir.path().join("depo.d");
    ok(&["batch", s(&xyz), "-o", s(&d)]);
    let pattern = dir.path().join("depo-%d.png");
    let legend = dir.path().join("key.svg");
    let out = ok(&[
        "render",
        s(&d),
        "-o",
        s(&pattern),
        "--width",
        "48",
        "--height",
        "32",
        "--legend",
        s(&legend),
    ]);
    assert!(out.contains("(ION)"), "{out}");
    let image = |i: u32| std::fs::read(dir.path().join(format!("depo-{i}.png"))).unwrap();
    assert_ne!(image(0), image(1));
    // The key's swatches: one colour per name.
    let svg = std::fs::read_to_string(&legend).unwrap();
    let swatches: Vec<&str> = svg
        .split("<circle cx=\"14\"")
        .skip(1)
        .filter_map(|c| c.split("fill=\"").nth(1)?.split('"').next())
        .collect();
    let colours: std::collections::BTreeSet<&&str> = swatches.iter().collect();
    assert_eq!((swatches.len(), colours.len()), (3, 3), "{svg}");
}

/// Frames converted apart can give one species name different looks (labels take the
/// palette by their place in the frame's list): a movie draws each name with one look.
/// Here the second frame lists the same particles in another order, B before A; its
/// image must be the first's.
#[test]
fn a_movie_keeps_each_species_look_across_frames() {
    let dir = tempfile::tempdir().unwrap();
    let atoms: Vec<(&str, [f32; 3])> = (0..216)
        .map(|i| {
            let p = [
                (i % 6) as f32 * 2.0,
                (i / 6 % 6) as f32 * 2.0,
                (i / 36) as f32 * 2.0,
            ];
            (if p[0] < 5.0 { "A" } else { "B" }, p)
        })
        .collect();
    let frame = |first: &str| {
        let mut t = format!("{}\nframe\n", atoms.len());
        for pass in [true, false] {
            for (name, p) in &atoms {
                if (*name == first) == pass {
                    t += &format!("{name} {} {} {}\n", p[0], p[1], p[2]);
                }
            }
        }
        t
    };
    let xyz = dir.path().join("ab.xyz");
    std::fs::write(&xyz, frame("A") + &frame("B")).unwrap();
    let d = dir.path().join("ab.d");
    ok(&["batch", s(&xyz), "-o", s(&d)]);
    let pattern = dir.path().join("ab-%d.png");
    let out = ok(&[
        "render",
        s(&d),
        "-o",
        s(&pattern),
        "--width",
        "40",
        "--height",
        "30",
        "--screen-error",
        "0",
    ]);
    assert!(
        out.contains("1 frame whose files gave a species another colour"),
        "{out}"
    );
    let image = |i: u32| std::fs::read(dir.path().join(format!("ab-{i}.png"))).unwrap();
    assert_eq!(image(0), image(1));
}

/// A radius a frame's data gives (here a raw sidecar's `radii`; a GSD frame's diameters
/// alike) is the frame's own: particles that grow over a run are drawn growing, and the
/// movie's summary says so.
#[test]
fn a_movie_draws_each_frame_with_its_own_radii() {
    let dir = tempfile::tempdir().unwrap();
    let positions: Vec<u8> = (0..64)
        .flat_map(|i| {
            [
                (i % 4) as f32 * 3.0,
                (i / 4 % 4) as f32 * 3.0,
                (i / 16) as f32 * 3.0,
            ]
        })
        .flat_map(f32::to_le_bytes)
        .collect();
    std::fs::write(dir.path().join("pos.f32"), &positions).unwrap();
    let mut inputs = Vec::new();
    for (step, radius) in [(0, 0.5), (100, 1.0)] {
        let sidecar = dir.path().join(format!("grow-{step}.raw.json"));
        std::fs::write(
            &sidecar,
            format!(
                r#"{{"mdlod_raw": 1, "positions": {{"file": "pos.f32", "type": "f32"}},
                    "radii": [{radius}], "timestep": {step}}}"#
            ),
        )
        .unwrap();
        inputs.push(sidecar);
    }
    let d = dir.path().join("grow.d");
    ok(&["batch", s(&inputs[0]), s(&inputs[1]), "-o", s(&d)]);
    let pattern = dir.path().join("grow-%d.png");
    let out = ok(&[
        "render",
        s(&d),
        "-o",
        s(&pattern),
        "--width",
        "48",
        "--height",
        "32",
        "--screen-error",
        "0",
    ]);
    assert!(
        out.contains(
            "species' radii change over the frames (atom: 0.500 to 1.000): each frame is drawn with its own"
        ),
        "{out}"
    );
    assert!(!out.contains("otherwise"), "{out}");
    // Larger spheres cover more of the background (white).
    let covered = |i: u32| {
        let (_, _, rgba) = read_png(&dir.path().join(format!("grow-{i}.png")));
        rgba.chunks(4).filter(|p| p[..3] != [255, 255, 255]).count()
    };
    assert!(
        covered(1) > covered(0) + 100,
        "{} {}",
        covered(0),
        covered(1)
    );
}

/// `--clip` cuts the data away in the sphere and splat modes (OVITO's Slice): the cut
/// face's particles are counted, a camera on the kept side is told where the face
/// looks, and the volume modes, which clip their samples by one plane, refuse two.
#[test]
fn clip_planes_cut_the_particles_away() {
    let dir = tempfile::tempdir().unwrap();
    let input = lammps_sample_path("cuag_alloy.unwrapped.dump");
    let file = dir.path().join("a.mdlod");
    ok(&["convert", s(&input), "-o", s(&file)]);
    let top = MdlodFile::open(&file).unwrap().nodes()[0];
    let mid = 0.5 * (top.bounds_min[0] + top.bounds_max[0]);
    let plane = format!("1,0,0,{mid}");
    let render = |name: &str, extra: &[&str]| {
        let png = dir.path().join(name);
        let mut args = vec![
            "render",
            s(&file),
            "-o",
            s(&png),
            "--width",
            "64",
            "--height",
            "48",
        ];
        args.extend_from_slice(extra);
        let out = ok(&args);
        (out, read_png(&png).2)
    };
    let (whole, whole_png) = render("whole.png", &[]);
    assert!(!whole.contains("--clip"), "{whole}");
    let mut notes = 0;
    for azimuth in ["0", "180"] {
        let (out, png) = render("cut.png", &["--clip", &plane, "--azimuth", azimuth]);
        assert!(out.contains("cut away by --clip"), "{out}");
        assert_ne!(png, whole_png);
        notes += usize::from(out.contains("on the kept side of the --clip plane"));
        // As OVITO's Slice: d is measured along the unit normal, however long n is.
        let (_, longer) = render(
            "cut2.png",
            &["--clip", &format!("2.5,0,0,{mid}"), "--azimuth", azimuth],
        );
        assert_eq!(longer, png);
    }
    assert_eq!(notes, 1, "one of two opposite cameras sees the face");
    // A slab by two facing planes, in the splat modes too; one of its faces always faces
    // the camera, so no note.
    let slab = format!("-1,0,0,{}", -(mid - 2.0));
    for mode in ["splat", "splat-over", "spheres"] {
        let (out, _) = render(
            "slab.png",
            &["--mode", mode, "--clip", &plane, "--clip", &slab],
        );
        assert!(out.contains("cut away by --clip"), "{mode}: {out}");
        assert!(!out.contains("kept side"), "{mode}: {out}");
    }
    // A plane that keeps nothing says so.
    let (out, _) = render(
        "none.png",
        &["--clip", &format!("1,0,0,{}", top.bounds_min[0] - 10.0)],
    );
    assert!(
        out.contains("nothing is drawn: the --clip planes cut every particle away"),
        "{out}"
    );
    let err = fails(&[
        "render",
        s(&file),
        "-o",
        s(&dir.path().join("d.png")),
        "--mode",
        "density",
        "--clip",
        &plane,
        "--clip",
        &slab,
    ]);
    assert!(err.contains("takes one --clip plane (2 given)"), "{err}");
    let err = fails(&[
        "render",
        s(&file),
        "-o",
        s(&dir.path().join("d.png")),
        "--clip",
        "0,0,0,1",
    ]);
    assert!(err.contains("a normal nx,ny,nz that is not zero"), "{err}");
    // A plane beyond the data cuts nothing: no face, no note about one.
    let (out, _) = render("far.png", &["--clip", "1,0,0,1e30"]);
    assert!(
        !out.contains("kept side") && !out.contains("cut away"),
        "{out}"
    );
    // Normals of any magnitude single precision can write are one direction.
    let (_, unit) = render("u.png", &["--clip", &plane]);
    for tiny_or_huge in ["1e-38", "3e38", "1e300"] {
        let (_, png) = render("t.png", &["--clip", &format!("{tiny_or_huge},0,0,{mid}")]);
        assert_eq!(png, unit, "{tiny_or_huge}");
    }
}

/// A fitted view frames the data clear of the label's panel, as of the legend's: a
/// long label over a block seen from above covered its top rows.
#[test]
fn a_fitted_view_keeps_the_data_from_under_the_label() {
    let dir = tempfile::tempdir().unwrap();
    let input = lammps_sample_path("cu_melt.custom.dump");
    let file = dir.path().join("m.mdlod");
    ok(&["convert", s(&input), "-o", s(&file)]);
    let png = dir.path().join("l.png");
    let out = ok(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--width",
        "600",
        "--height",
        "400",
        "--label",
        "copper melt, timestep {timestep}",
        "--text-scale",
        "2",
        "--look-along",
        "0,0,-1",
        "--ortho",
    ]);
    assert!(out.contains("wrote"), "{out}");
    assert!(!out.contains("covers drawn particles"), "{out}");
}

/// `--legend-in-image` draws the legend into the picture: from a given view only the
/// panel in the corner asked for changes, a fitted view frames the data clear of it,
/// every image of a movie gets it, and an image too small is refused.
/// `--label`: each image gets its own values in the panel's corner and nothing else
/// changes; a placeholder it does not fill, and the legend's corner, are refused before
/// anything is drawn; a value the frames lack is noted.
#[test]
fn a_label_shows_each_frames_values_in_its_corner() {
    let dir = tempfile::tempdir().unwrap();
    let input = lammps_sample_path("cu_melt.custom.dump");
    let d = |n: &str| dir.path().join(n);
    let file = d("m.mdlod");
    ok(&["convert", s(&input), "-o", s(&file)]);
    let base = [
        "--width",
        "160",
        "--height",
        "120",
        "--background",
        "#000000",
    ];
    let view = d("v.json");
    ok(&[
        &["render", s(&file), "-o", s(&d("plain.png"))][..],
        &base,
        &["--save-view", s(&view)],
    ]
    .concat());
    ok(&[
        &["render", s(&file), "-o", s(&d("with.png"))][..],
        &base,
        &[
            "--view",
            s(&view),
            "--label",
            "step {timestep}",
            "--label-corner",
            "bottom-right",
        ],
    ]
    .concat());
    let ((w, h, a), (_, _, b)) = (read_png(&d("plain.png")), read_png(&d("with.png")));
    let (mut inside, mut outside) = (0, 0);
    for y in 0..h {
        for x in 0..w {
            let i = 4 * (y * w + x) as usize;
            if a[i..i + 4] != b[i..i + 4] {
                // "step 500": 8 characters of 7 px and a margin, one line of 22 px.
                if x >= w - 8 - (14 + 7 * 8) && y >= h - 8 - 22 {
                    inside += 1;
                } else {
                    outside += 1;
                }
            }
        }
    }
    assert!(
        outside == 0 && inside > 500,
        "{inside} inside, {outside} outside"
    );
    // A movie: each frame's own timestep, so the images' corners differ.
    let movie = d("m.d");
    ok(&["batch", s(&input), "-o", s(&movie)]);
    let out = ok(&[
        &["render", s(&movie), "-o", s(&d("f-%d.png"))][..],
        &base,
        &["--label", "step {timestep} t={time}"],
    ]
    .concat());
    let corner = |png: &str| {
        let (w, _, px) = read_png(&d(png));
        (0..30u32)
            .flat_map(|y| (0..80u32).map(move |x| (x, y)))
            .map(|(x, y)| px[4 * (y * w + x) as usize])
            .collect::<Vec<u8>>()
    };
    assert_ne!(corner("f-0.png"), corner("f-1.png"));
    assert!(
        !out.contains("records no time") && !out.contains("replaces"),
        "{out}"
    );
    // `--dt` over recorded times (a run of variable timestep records the true ones):
    // said, naming them.
    let out = ok(&[
        &["render", s(&movie), "-o", s(&d("g-%d.png"))][..],
        &base,
        &["--label", "t={time}", "--dt", "1"],
    ]
    .concat());
    assert!(
        out.contains("--label: --dt 1 replaces the recorded times, ")
            && out.contains("(leave out --dt to show the recorded time)"),
        "{out}"
    );
    // A dump without a time: said, and `?` drawn.
    std::fs::write(
        d("nt.dump"),
        "ITEM: TIMESTEP\n7\nITEM: NUMBER OF ATOMS\n2\nITEM: BOX BOUNDS pp pp pp\n0 4\n0 4\n0 4\n\
         ITEM: ATOMS id type x y z\n1 1 1 1 1\n2 1 3 3 3\n",
    )
    .unwrap();
    ok(&["convert", s(&d("nt.dump")), "-o", s(&d("nt.mdlod"))]);
    let out = ok(&[
        &["render", s(&d("nt.mdlod")), "-o", s(&d("nt.png"))][..],
        &base,
        &["--label", "t={time}"],
    ]
    .concat());
    assert!(
        out.contains("--label: the file records no time: {time} shows ?")
            && out.contains("--dt DT gives it"),
        "{out}"
    );
    let question = corner("nt.png");
    // `--dt`: the time is the timestep (7) times it; drawn, not `?`.
    let out = ok(&[
        &["render", s(&d("nt.mdlod")), "-o", s(&d("nt.png"))][..],
        &base,
        &["--label", "t={time}", "--dt", "0.002"],
    ]
    .concat());
    assert!(!out.contains("records no time"), "{out}");
    assert_ne!(corner("nt.png"), question);
    for (extra, message) in [
        (&["--dt", "0.002"][..], "--dt has no effect without --label"),
        (
            &["--label-corner", "bottom-left"][..],
            "--label-corner has no effect without --label",
        ),
        (&["--label", " "][..], "an empty label draws an empty panel"),
        (
            &["--label", "step {timestep}", "--dt", "0.002"][..],
            "--dt has no effect without {time} in a --label",
        ),
        (
            &["--label", "t={time}", "--dt", "0"][..],
            "must be a finite number above 0",
        ),
        (
            &["--label", "t={time:2}"][..],
            "`:2` is no number of decimals",
        ),
        (
            &["--label", "{step}"][..],
            "{step} is no value a label fills in",
        ),
        // A misspelt placeholder beside {time} is the fault named, not --dt.
        (
            &["--label", "t={time} {bogus}", "--dt", "0.002"][..],
            "{bogus} is no value a label fills in",
        ),
        (
            &["--label", "a label far too long for an image of 160 pixels"][..],
            "--label: a 160×120 image cannot hold the label",
        ),
        // Values that widen it past the image: refused before anything is drawn.
        (
            &["--label", "{source} {source} {source} {source}"][..],
            "cannot hold the label with the file's values",
        ),
        (
            &["--label", "x", "--legend-in-image=top-left"][..],
            "both draw at the top-left corner",
        ),
    ] {
        let png = d("no.png");
        let e = fails(&[&["render", s(&file), "-o", s(&png)][..], &base, extra].concat());
        assert!(e.contains(message), "{e}");
        assert!(!png.exists());
    }
}

/// `--legend-category`: a key of named values in the colour map's colours instead of
/// the bar, without the values hidden; refused without a colour map or a legend.
/// A species key lists the species in one order whatever order the dump's atoms came
/// in: two frames of one run, their elements first seen in other orders, key alike.
#[test]
fn a_species_key_lists_names_in_one_order_for_every_frame() {
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| dir.path().join(n);
    let mut dump = String::new();
    for (t, order) in [(0, ["O", "H", "C"]), (100, ["H", "C", "O"])] {
        dump.push_str(&format!(
            "ITEM: TIMESTEP\n{t}\nITEM: NUMBER OF ATOMS\n6\nITEM: BOX BOUNDS pp pp pp\n0 10\n0 10\n0 10\nITEM: ATOMS id element x y z\n"
        ));
        for (i, e) in order.iter().chain(order.iter()).enumerate() {
            dump.push_str(&format!("{} {e} {} {} 5\n", i + 1, 1 + i, 2 + i % 3));
        }
    }
    std::fs::write(d("run.lammpstrj"), dump).unwrap();
    ok(&["batch", s(&d("run.lammpstrj")), "-o", s(&d("run.d"))]);
    for t in [0, 100] {
        let frame = d(&format!("run.d/frame-{t}.mdlod"));
        let svg = d(&format!("k{t}.svg"));
        let png = d(&format!("k{t}.png"));
        ok(&[
            "render",
            s(&frame),
            "-o",
            s(&png),
            "--width",
            "96",
            "--height",
            "64",
            "--legend",
            s(&svg),
        ]);
        let key = std::fs::read_to_string(&svg).unwrap();
        let at = |e: &str| key.find(&format!(">{e}</text>")).unwrap();
        assert!(at("C") < at("H") && at("H") < at("O"), "frame {t}: {key}");
    }
}

#[test]
fn a_legend_can_name_the_values_of_categories() {
    let dir = tempfile::tempdir().unwrap();
    let input = lammps_sample_path("cu_melt.custom.dump");
    let d = |n: &str| dir.path().join(n);
    let file = d("m.mdlod");
    ok(&[
        "convert",
        s(&input),
        "-o",
        s(&file),
        "--last",
        "--attribute",
        "c_pe",
    ]);
    let (png, svg) = (d("k.png"), d("k.svg"));
    let base = [
        "render",
        s(&file),
        "-o",
        s(&png),
        "--width",
        "48",
        "--height",
        "32",
    ];
    let out = ok(&[
        &base[..],
        &["--colour-map", "magma", "--legend", s(&svg)],
        &[
            "--legend-category=-3.5=bulk",
            "--legend-category=-3.0=surface",
        ],
        &["--legend-category=-2.9=adatom", "--hide-attribute=-2.95:"],
    ]
    .concat());
    assert!(out.contains("2 categories of c_pe"), "{out}");
    let key = std::fs::read_to_string(&svg).unwrap();
    assert!(
        key.contains(">bulk</text>") && key.contains(">surface</text>") && !key.contains("adatom"),
        "{key}"
    );
    assert!(key.contains(">c_pe</text>"), "{key}");
    for (extra, message) in [
        (
            &["--legend-category", "1=a", "--legend", s(&svg)][..],
            "it needs --colour-map",
        ),
        (
            &["--legend-category", "1=a", "--colour-map", "grey"][..],
            "give --legend FILE.svg",
        ),
        (
            &[
                "--legend-category",
                "x=a",
                "--colour-map",
                "grey",
                "--legend",
                s(&svg),
            ][..],
            "\"x\" is not a finite number",
        ),
        (
            &[
                "--legend-category",
                "-1=a",
                "--legend-category",
                "-1.0=b",
                "--colour-map",
                "grey",
                "--legend",
                s(&svg),
            ][..],
            "the value -1 is named twice (first \"a\")",
        ),
    ] {
        let e = fails(&[&base[..], extra].concat());
        assert!(e.contains(message), "{extra:?}: {e}");
    }
}

#[test]
fn a_legend_drawn_into_the_image_changes_only_its_corner() {
    let dir = tempfile::tempdir().unwrap();
    let input = lammps_sample_path("cu_melt.custom.dump");
    let file = dir.path().join("m.mdlod");
    ok(&["convert", s(&input), "-o", s(&file), "--attribute", "c_pe"]);
    let (plain, with) = (dir.path().join("plain.png"), dir.path().join("with.png"));
    let base = [
        "--width",
        "480",
        "--height",
        "240",
        "--colour-map",
        "viridis",
        "--background",
        "#000000",
    ];
    let view = dir.path().join("v.json");
    ok(&[
        &["render", s(&file), "-o", s(&plain)][..],
        &base,
        &["--save-view", s(&view)],
    ]
    .concat());
    let out = ok(&[
        &["render", s(&file), "-o", s(&with)][..],
        &base,
        &["--legend-in-image", "--legend-title", "E_pot (eV)"],
        &["--view", s(&view)],
    ]
    .concat());
    assert!(out.contains("legend drawn into"), "{out}");
    // The saved view was fitted without the panel: the data under it is said.
    assert!(
        out.contains("note: --legend-in-image covers drawn particles in the image")
            && out.contains("is not fitted around the panel"),
        "{out}"
    );
    let ((w, h, a), (_, _, b)) = (read_png(&plain), read_png(&with));
    // The panel: 360 × 66 pixels, 8 from the bottom right corner.
    let panel = |x: u32, y: u32| x >= w - 8 - 360 && x < w - 8 && y >= h - 8 - 66 && y < h - 8;
    let (mut inside, mut outside) = (0, 0);
    for y in 0..h {
        for x in 0..w {
            let i = 4 * (y * w + x) as usize;
            if a[i..i + 4] != b[i..i + 4] {
                if panel(x, y) {
                    inside += 1;
                } else {
                    outside += 1;
                }
            }
        }
    }
    assert_eq!(outside, 0);
    assert!(
        inside > 360 * 66 / 2,
        "{inside} pixels of the panel changed"
    );
    // Fitted, the data lies wholly above the panel's band or wholly beside it (the
    // plain fit's data reaches into the corner).
    let room = [376, 82];
    let clear = |png: &Path| {
        let (_, _, px) = read_png(png);
        let data: Vec<(u32, u32)> = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .filter(|&(x, y)| !panel(x, y) && px[4 * (y * w + x) as usize..][..3] != [0, 0, 0])
            .collect();
        assert!(!data.is_empty());
        let above = data.iter().all(|&(_, y)| y < h - room[1]);
        let beside = data.iter().all(|&(x, _)| x < w - room[0]);
        above || beside
    };
    assert!(
        !clear(&plain),
        "the plain fit already leaves the corner free"
    );
    let out = ok(&[
        &["render", s(&file), "-o", s(&with)][..],
        &base,
        &["--legend-in-image", "--legend-title", "E_pot (eV)"],
    ]
    .concat());
    assert!(clear(&with), "the fitted data reaches under the legend");
    assert!(!out.contains("covers drawn particles"), "{out}");
    // A turntable keeps the corner free in every view too.
    let turn = dir.path().join("turn-%d.png");
    ok(&[
        &["render", s(&file), "-o", s(&turn)][..],
        &base,
        &["--legend-in-image", "--turntable", "3"],
    ]
    .concat());
    for i in 0..3 {
        let view = dir.path().join(format!("turn-{i}.png"));
        assert!(
            clear(&view),
            "turntable view {i}: the data reaches under the legend"
        );
    }
    // A short, wide image: the bands above the panel and beside it both leave out the
    // image's centre; the data is framed beside the panel, the larger of the two.
    let short = dir.path().join("short.png");
    ok(&[
        "render",
        s(&file),
        "-o",
        s(&short),
        "--width",
        "640",
        "--height",
        "120",
        "--colour-map",
        "viridis",
        "--background",
        "#000000",
        "--legend-in-image",
    ]);
    let (sw, sh, px) = read_png(&short);
    let data: Vec<(u32, u32)> = (0..sh)
        .flat_map(|y| (0..sw).map(move |x| (x, y)))
        .filter(|&(x, y)| {
            let in_panel = x >= sw - 8 - 360 && y >= sh - 8 - 66;
            !in_panel && px[4 * (y * sw + x) as usize..][..3] != [0, 0, 0]
        })
        .collect();
    let right = data.iter().map(|&(x, _)| x).max().unwrap();
    let (top, bottom) = (
        data.iter().map(|&(_, y)| y).min().unwrap(),
        data.iter().map(|&(_, y)| y).max().unwrap(),
    );
    assert!(right < sw - room[0], "the data reaches x = {right}");
    // Filling the band's height (120 px less the margins), not shrunk into 38 px.
    assert!(bottom - top > 80, "the data spans rows {top} to {bottom}");
    // Top left: the panel moves there.
    ok(&[
        &["render", s(&file), "-o", s(&with)][..],
        &base,
        &["--legend-in-image=top-left"],
    ]
    .concat());
    let (_, _, c) = read_png(&with);
    assert_ne!(
        a[4 * (10 * w + 10) as usize..][..4],
        c[4 * (10 * w + 10) as usize..][..4]
    );
    assert_eq!(a[a.len() - 40..], c[c.len() - 40..]);
    // Too small for the panel: refused with the size it needs, before anything is drawn.
    let small = dir.path().join("small.png");
    let e = fails(&[
        "render",
        s(&file),
        "-o",
        s(&small),
        "--width",
        "200",
        "--height",
        "120",
        "--colour-map",
        "viridis",
        "--legend-in-image",
    ]);
    assert!(
        e.contains("cannot hold the legend") && e.contains("at least 376×82"),
        "{e}"
    );
    assert!(!small.exists());
    // Room for the panel but none for the data beside or above it: refused too (the data
    // was drawn under the panel).
    let e = fails(&[
        "render",
        s(&file),
        "-o",
        s(&small),
        "--width",
        "400",
        "--height",
        "100",
        "--colour-map",
        "viridis",
        "--legend-in-image",
    ]);
    assert!(
        e.contains("leaves the data only 400×18 pixels above it or 24×100 beside it"),
        "{e}"
    );
    assert!(!small.exists());
    // Corner names in any case; a character the image's font lacks is named.
    let out = ok(&[
        &["render", s(&file), "-o", s(&with)][..],
        &base,
        &["--legend-in-image=Top-Left", "--legend-title", "E (日)"],
    ]
    .concat());
    assert!(out.contains("the image's font has no '日'"), "{out}");
    // Before the file, the flag takes no value of it.
    ok(&[
        &["render", "--legend-in-image", s(&file), "-o", s(&with)][..],
        &base,
    ]
    .concat());
    let e = fails(&["render", s(&file), "-o", s(&with), "--legend-title", "x"]);
    assert!(e.contains("--legend-title titles a legend"), "{e}");
    // Without a colour map, the key of the species shown.
    let out = ok(&[
        &["render", s(&file), "-o", s(&with)][..],
        &["--width", "480", "--height", "240", "--legend-in-image"],
    ]
    .concat());
    assert!(out.contains("(1 species in their colours)"), "{out}");
    // Every species hidden: the key is empty, and said to be.
    let out = ok(&[
        &["render", s(&file), "-o", s(&with)][..],
        &["--width", "480", "--height", "240", "--legend-in-image"],
        &["--hide-species", "1"],
    ]
    .concat());
    assert!(out.contains("(an empty key: no species is shown)"), "{out}");
    // A movie: every frame gets the legend.
    let d = dir.path().join("m.d");
    ok(&["batch", s(&input), "-o", s(&d), "--attribute", "c_pe"]);
    let pattern = dir.path().join("f-%d.png");
    let out = ok(&[
        &["render", s(&d), "-o", s(&pattern)][..],
        &base,
        &["--legend-in-image"],
    ]
    .concat());
    assert!(out.contains("legend drawn into each of the"), "{out}");
    for i in 0..2 {
        let (_, _, f) = read_png(&dir.path().join(format!("f-{i}.png")));
        let at = 4 * ((h - 8 - 33) * w + (w - 8 - 180)) as usize;
        assert_ne!(f[at..at + 3], a[at..at + 3], "frame {i}");
    }
}

/// A movie's in-image key names the species of every frame: its room is kept for all of
/// them, also where the first frame has fewer (ions that come later), so the panel
/// covers no particle of any frame.
#[test]
fn a_movies_legend_keeps_room_for_species_that_come_later() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("ions.lammpstrj");
    let mut text = String::new();
    for (t, kinds) in [(0, 2), (100, 6)] {
        text.push_str(&format!(
            "ITEM: TIMESTEP\n{t}\nITEM: NUMBER OF ATOMS\n1000\nITEM: BOX BOUNDS pp pp pp\n\
             0 40\n0 20\n0 20\nITEM: ATOMS id type x y z\n"
        ));
        for i in 0..1000 {
            let (x, y, z) = (i % 20, (i / 20) % 10, i / 200);
            let kind = 1 + i % kinds;
            text.push_str(&format!(
                "{} {kind} {} {} {}\n",
                i + 1,
                2 * x + 1,
                2 * y + 1,
                4 * z + 1
            ));
        }
    }
    std::fs::write(&dump, text).unwrap();
    let d = dir.path().join("ions.d");
    ok(&["batch", s(&dump), "-o", s(&d)]);
    let (with, plain) = (
        dir.path().join("with-%d.png"),
        dir.path().join("plain-%d.png"),
    );
    let view = dir.path().join("v.json");
    // Seen side on, the slab fills the image's width above a short key.
    let base = [
        "--width",
        "480",
        "--height",
        "320",
        "--background",
        "#000000",
        "--look-along",
        "0,1,0",
        "--ortho",
    ];
    let out = ok(&[
        &["render", s(&d), "-o", s(&with)][..],
        &base,
        &["--legend-in-image", "--save-view", s(&view)],
    ]
    .concat());
    assert!(out.contains("(6 species in their colours)"), "{out}");
    ok(&[
        &["render", s(&d), "-o", s(&plain)][..],
        &base,
        &["--view", s(&view)],
    ]
    .concat());
    for i in 0..2 {
        let (w, h, a) = read_png(&dir.path().join(format!("with-{i}.png")));
        let (_, _, b) = read_png(&dir.path().join(format!("plain-{i}.png")));
        // The panel: the box around the pixels the legend changed.
        let (mut x0, mut y0, mut x1, mut y1) = (w, h, 0, 0);
        for y in 0..h {
            for x in 0..w {
                let k = 4 * (y * w + x) as usize;
                if a[k..k + 4] != b[k..k + 4] {
                    (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
                }
            }
        }
        assert!(
            x1 > x0 && y1 - y0 > 100,
            "frame {i}: panel {x0},{y0} to {x1},{y1}"
        );
        let under = (y0..=y1)
            .flat_map(|y| (x0..=x1).map(move |x| (x, y)))
            .filter(|&(x, y)| b[4 * (y * w + x) as usize..][..3] != [0, 0, 0])
            .count();
        assert_eq!(
            under, 0,
            "frame {i}: the legend covers {under} pixels of particles"
        );
    }
}

/// Hiding a species a still's frame lacks hides nothing there: said, and drawn (a
/// script run over every frame, ions that come later), where the name is of the frame's
/// kind (a name among names, a type among types); a name that differs from one of the
/// frame's in case only is a misspelling, and a movie, which knows every frame, refuses
/// a name none has. Names come one per flag or as a list; a type-number file's hint
/// names its types.
#[test]
fn hiding_a_species_a_frame_lacks_is_said_not_refused() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("three.lammpstrj");
    let mut text = String::from(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n27\nITEM: BOX BOUNDS pp pp pp\n\
         0 6\n0 6\n0 6\nITEM: ATOMS id type x y z\n",
    );
    for i in 0..27 {
        let (x, y, z) = (i % 3, (i / 3) % 3, i / 9);
        text.push_str(&format!(
            "{} {} {} {} {}\n",
            i + 1,
            1 + i % 3,
            2 * x + 1,
            2 * y + 1,
            2 * z + 1
        ));
    }
    std::fs::write(&dump, text).unwrap();
    let file = dir.path().join("three.mdlod");
    ok(&[
        "convert",
        s(&dump),
        "-o",
        s(&file),
        "--species-name",
        "1=C1A",
        "--species-name",
        "2=PO4",
        "--species-name",
        "3=W",
    ]);
    let png = dir.path().join("x.png");
    let out = ok(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--width",
        "64",
        "--height",
        "48",
        "--hide-species",
        "NA",
        "--hide-species",
        "W",
    ]);
    assert!(
        out.contains("note: --hide-species NA: no particle of this frame is NA (its species are C1A, PO4, W): nothing of it to hide here"),
        "{out}"
    );
    assert!(out.contains("18 particles"), "{out}");
    // A list hides the same.
    let list = ok(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--width",
        "64",
        "--height",
        "48",
        "--hide-species",
        "NA, W,CL",
    ]);
    assert!(list.contains("--hide-species CL,NA: no particle"), "{list}");
    assert!(list.contains("18 particles"), "{list}");
    // A name the frame spells in another case is a misspelling.
    let e = fails(&["render", s(&file), "-o", s(&png), "--hide-species", "w"]);
    assert!(
        e.contains("no species named \"w\"; did you mean \"W\"?"),
        "{e}"
    );
    // So is a colour or radius for it (one figure script over every frame of the run);
    // a name the frame spells in another case is still a misspelling.
    let out = ok(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--width",
        "64",
        "--height",
        "48",
        "--species-colour",
        "NA=red",
        "--species-radius",
        "NA=1.2",
    ]);
    assert!(
        out.contains("note: no particle of this frame is NA (its species are C1A, PO4, W): the options naming it do nothing here"),
        "{out}"
    );
    let e = fails(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--species-colour",
        "w=red",
    ]);
    assert!(
        e.contains("no species named \"w\"; did you mean \"W\"?"),
        "{e}"
    );
    // Stray commas and names of several words are refused.
    for bad in ["W,", "W NA"] {
        let e = fails(&["render", s(&file), "-o", s(&png), "--hide-species", bad]);
        assert!(
            e.contains("an empty name") || e.contains("holds no spaces"),
            "{e}"
        );
    }
    // A movie knows every frame's species: a name none has is refused.
    let d = dir.path().join("three.d");
    ok(&["batch", s(&dump), "-o", s(&d)]);
    let frames = dir.path().join("f-%d.png");
    let out = fails(&[
        "render",
        s(&d),
        "-o",
        s(&frames),
        "--width",
        "64",
        "--height",
        "48",
        "--hide-species",
        "7",
    ]);
    assert!(
        out.contains("has a species named \"7\" (its frames have 1, 2, 3)"),
        "{out}"
    );
    // Type numbers: the hint lists them, and names no one type for the user's name; a
    // name that is no type number is refused for hiding too (it cannot be a type of
    // another frame).
    let numbered = dir.path().join("numbered.mdlod");
    ok(&["convert", s(&dump), "-o", s(&numbered)]);
    let e = fails(&["render", s(&numbered), "-o", s(&png), "--hide-species", "W"]);
    assert!(e.contains("no species named \"W\""), "{e}");
    let out = ok(&[
        "render",
        s(&numbered),
        "-o",
        s(&png),
        "--width",
        "64",
        "--height",
        "48",
        "--hide-species",
        "3,6",
    ]);
    assert!(
        out.contains("--hide-species 6: no particle of this frame is 6"),
        "{out}"
    );
    let e = fails(&[
        "render",
        s(&numbered),
        "-o",
        s(&png),
        "--species-colour",
        "water=blue",
    ]);
    assert!(
        e.contains(
            "name the type here (one of 1, 2, 3), or convert with --species-name TYPE=water"
        ),
        "{e}"
    );
}

/// Ids kept as an attribute past what 16 bits tell apart are said to be so when
/// converted (not given the logarithm's remedy, which keeps no id apart either), and a
/// hidden range narrower than a step says which values it hides.
#[test]
fn ids_past_sixteen_bits_are_said_to_share_steps() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("mol.lammpstrj");
    let n = 70_000;
    let mut text = format!(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{n}\nITEM: BOX BOUNDS pp pp pp\n0 140\n0 100\n\
         0 10\nITEM: ATOMS id mol type x y z\n"
    );
    for i in 0..n {
        let (x, y, z) = (i % 70, (i / 70) % 50, i / 3500);
        text.push_str(&format!(
            "{} {} 1 {} {} {}\n",
            i + 1,
            3 * i + 1,
            2 * x,
            2 * y,
            z / 2
        ));
    }
    std::fs::write(&dump, text).unwrap();
    let file = dir.path().join("mol.mdlod");
    let out = ok(&["convert", s(&dump), "-o", s(&file), "--attribute", "mol"]);
    assert!(
        out.contains("attribute mol holds whole numbers from 1 to 209998 (ids?)")
            && !out.contains("--attribute-log10 keeps its logarithm"),
        "{out}"
    );
    let png = dir.path().join("m.png");
    let out = ok(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--width",
        "64",
        "--height",
        "48",
        "--hide-attribute",
        "4:4",
    ]);
    assert!(
        out.contains("--hide-attribute 4:4 is narrower than one 16-bit step of mol in this file"),
        "{out}"
    );
    // A range wider than a step: nothing to say.
    let out = ok(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--width",
        "64",
        "--height",
        "48",
        "--hide-attribute",
        "5:500",
    ]);
    assert!(!out.contains("narrower than one 16-bit step"), "{out}");
    // Ids within 65 536 of one another keep a step each: no note of sharing steps or of
    // decades, but, their steps above a half, that ends halfway between them are unsafe.
    let few = dir.path().join("few.lammpstrj");
    let text = std::fs::read_to_string(&dump).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let mut short = String::new();
    for (i, line) in lines.iter().enumerate().take(9 + 20_000) {
        short.push_str(if i == 3 { "20000" } else { line });
        short.push('\n');
    }
    std::fs::write(&few, short).unwrap();
    let file = dir.path().join("few.mdlod");
    let out = ok(&["convert", s(&few), "-o", s(&file), "--attribute", "mol"]);
    assert!(
        !out.contains("--attribute-log10")
            && !out.contains("more than 16 bits tell apart")
            && out.contains("each in a 16-bit step of its own (a step is 0.92)"),
        "{out}"
    );
    let out = ok(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--width",
        "64",
        "--height",
        "48",
        "--hide-attribute",
        "300:300",
    ]);
    assert!(!out.contains("narrower than one 16-bit step"), "{out}");
}

/// `--legend` writes what the colours mean as SVG: the colour map's bar over the range
/// shown (a movie's: every frame's), the species shown in their colours, the density's
/// transfer function; a name that is no SVG is refused before anything is drawn.
#[test]
fn a_legend_says_what_the_colours_mean() {
    let dir = tempfile::tempdir().unwrap();
    let input = lammps_sample_path("cu_melt.custom.dump");
    let file = dir.path().join("m.mdlod");
    ok(&["convert", s(&input), "-o", s(&file), "--attribute", "c_pe"]);
    let png = dir.path().join("m.png");
    let svg = dir.path().join("m.svg");
    let render = |extra: &[&str]| {
        let mut args = vec![
            "render",
            s(&file),
            "-o",
            s(&png),
            "--width",
            "32",
            "--height",
            "24",
            "--legend",
            s(&svg),
        ];
        args.extend_from_slice(extra);
        let out = ok(&args);
        (out, std::fs::read_to_string(&svg).unwrap())
    };
    let (out, bar) = render(&["--colour-map", "viridis", "--attribute-range", "-4:-2"]);
    assert!(
        out.contains("legend written to") && out.contains("the colour map over c_pe"),
        "{out}"
    );
    assert!(
        bar.starts_with("<svg") && bar.contains(">c_pe</text>"),
        "{bar}"
    );
    assert!(
        bar.contains(">\u{2212}4.0</text>")
            && bar.contains(">\u{2212}2.0</text>")
            && bar.contains(">\u{2212}3.0</text>"),
        "{bar}"
    );
    let (_, key) = render(&["--species-colour", "1=#ff0000"]);
    assert!(
        key.contains(r##"fill="#ff0000""##) && key.contains(">1</text>"),
        "{key}"
    );
    let (_, density) = render(&["--mode", "density"]);
    assert!(density.contains("volume fraction"), "{density}");
    // Density on a log scale: the bar says so and ticks its decades.
    let (out, density) = render(&["--mode", "density", "--log-scale", "--density-max", "20"]);
    assert!(
        out.contains("from 0.002 (clear)") && out.contains("on a log scale"),
        "{out}"
    );
    assert!(
        density.contains("(log scale)") && density.contains(">0.002</text>"),
        "{density}"
    );
    assert!(
        density.contains(">0.1</text>") && density.contains(">1</text>"),
        "{density}"
    );
    // A movie writes one legend, over every frame's range.
    let d = dir.path().join("m.d");
    ok(&["batch", s(&input), "-o", s(&d), "--attribute", "c_pe"]);
    let pattern = dir.path().join("f-%d.png");
    let out = ok(&[
        "render",
        s(&d),
        "-o",
        s(&pattern),
        "--width",
        "32",
        "--height",
        "24",
        "--colour-map",
        "magma",
        "--legend",
        s(&svg),
    ]);
    assert_eq!(out.matches("legend written to").count(), 1, "{out}");
    let e = fails(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--legend",
        s(&dir.path().join("l.png")),
    ]);
    assert!(e.contains("name it .svg"), "{e}");

    // A title of the user's; as for -o, the directory must exist.
    let titled = dir.path().join("legends").join("t.svg");
    let e = fails(&["render", s(&file), "-o", s(&png), "--legend", s(&titled)]);
    assert!(e.contains("does not exist"), "{e}");
    std::fs::create_dir(dir.path().join("legends")).unwrap();
    ok(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--width",
        "32",
        "--height",
        "24",
        "--colour-map",
        "magma",
        "--legend",
        s(&titled),
        "--legend-title",
        "E_pot (eV)",
    ]);
    assert!(std::fs::read_to_string(&titled)
        .unwrap()
        .contains(">E_pot (eV)</text>"));

    // The key lists the species the picture shows: a plane cutting B away leaves A.
    let xyz = dir.path().join("ab.xyz");
    let mut text = String::from("54\ntwo blocks\n");
    for i in 0..54 {
        let (name, x) = if i < 27 { ("A", 0.0) } else { ("B", 10.0) };
        let k = i % 27;
        text += &format!(
            "{name} {} {} {}\n",
            x + (k % 3) as f32,
            (k / 3 % 3) as f32,
            (k / 9) as f32
        );
    }
    std::fs::write(&xyz, text).unwrap();
    let ab = dir.path().join("ab.mdlod");
    ok(&["convert", s(&xyz), "-o", s(&ab)]);
    let key = |extra: &[&str]| {
        let mut args = vec![
            "render",
            s(&ab),
            "-o",
            s(&png),
            "--width",
            "32",
            "--height",
            "24",
            "--legend",
            s(&svg),
        ];
        args.extend_from_slice(extra);
        ok(&args);
        std::fs::read_to_string(&svg).unwrap()
    };
    let both = key(&[]);
    assert!(
        both.contains(">A</text>") && both.contains(">B</text>"),
        "{both}"
    );
    let cut = key(&["--clip", "1,0,0,6"]);
    assert!(
        cut.contains(">A</text>") && !cut.contains(">B</text>"),
        "{cut}"
    );

    // A constant attribute: one colour, said in the summary and the bar.
    let flat = dir.path().join("flat.lammpstrj");
    let mut dump = String::from(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n8\nITEM: BOX BOUNDS pp pp pp\n0 4\n0 4\n0 4\n\
         ITEM: ATOMS id type x y z c_pe\n",
    );
    for i in 0..8 {
        dump += &format!(
            "{} 1 {} {} {} -3.54\n",
            i + 1,
            i % 2 * 2,
            i / 2 % 2 * 2,
            i / 4 * 2
        );
    }
    std::fs::write(&flat, dump).unwrap();
    let flat_file = dir.path().join("flat.mdlod");
    ok(&[
        "convert",
        s(&flat),
        "-o",
        s(&flat_file),
        "--attribute",
        "c_pe",
    ]);
    let out = ok(&[
        "render",
        s(&flat_file),
        "-o",
        s(&png),
        "--width",
        "32",
        "--height",
        "24",
        "--colour-map",
        "viridis",
        "--legend",
        s(&svg),
    ]);
    assert!(
        out.contains("c_pe is constant in this file (-3.54): every particle takes the map's"),
        "{out}"
    );
    // Splats lit by it all give the same light, a projection's map or not.
    for extra in [&[][..], &["--colour-map", "viridis"]] {
        let mut args = vec!["render", s(&flat_file), "-o", s(&png), "--mode", "splat"];
        args.extend([
            "--intensity",
            "attribute",
            "--width",
            "32",
            "--height",
            "24",
        ]);
        args.extend_from_slice(extra);
        let out = ok(&args);
        assert!(
            out.contains("constant in this file (-3.54): every splat is lit alike (its light its disk's area)"),
            "{extra:?}: {out}"
        );
    }
    let out = ok(&[
        "render",
        s(&flat_file),
        "-o",
        s(&png),
        "--width",
        "32",
        "--height",
        "24",
        "--colour-map",
        "viridis",
        "--log-scale",
    ]);
    assert!(
        out.contains("--log-scale left unused: the attribute is constant"),
        "{out}"
    );
    assert!(std::fs::read_to_string(&svg)
        .unwrap()
        .contains("every value -3.54 (constant)"));
    // A movie of frames that all hold the one value says so too.
    let two = dir.path().join("two.lammpstrj");
    let text = std::fs::read_to_string(&flat).unwrap();
    std::fs::write(
        &two,
        text.clone() + &text.replacen("TIMESTEP\n0", "TIMESTEP\n10", 1),
    )
    .unwrap();
    let movie = dir.path().join("two.d");
    ok(&["batch", s(&two), "-o", s(&movie), "--attribute", "c_pe"]);
    let out = ok(&[
        "render",
        s(&movie),
        "-o",
        s(&dir.path().join("m-%d.png")),
        "--width",
        "32",
        "--height",
        "24",
        "--colour-map",
        "viridis",
    ]);
    assert!(
        out.contains(
            "c_pe is -3.54 in every frame (constant): every particle takes the map's last colour"
        ),
        "{out}"
    );
    // Frames that draw nothing are named.
    let out = ok(&[
        "render",
        s(&movie),
        "-o",
        s(&dir.path().join("e-%d.png")),
        "--width",
        "32",
        "--height",
        "24",
        "--hide-attribute",
        ":0",
    ]);
    assert!(
        out.contains("note: 2 of the 2 frames draw nothing (timestep 0, 10)"),
        "{out}"
    );
}

/// `--cell` draws the simulation cell's edges over the picture, in a colour given or one
/// that contrasts with the background; a file without a cell says so, and the S-NDF
/// mode, which shades no depth to hide edges behind, refuses it.
#[test]
fn the_cell_is_drawn_over_the_picture() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("lj.mdlod");
    ok(&[
        "convert",
        s(&lammps_sample_path("lj_triclinic.custom.bin")),
        "-o",
        s(&file),
    ]);
    let png = dir.path().join("c.png");
    let render = |extra: &[&str]| {
        let mut args = vec![
            "render",
            s(&file),
            "-o",
            s(&png),
            "--width",
            "96",
            "--height",
            "72",
        ];
        args.extend_from_slice(extra);
        ok(&args);
        read_png(&png).2
    };
    // Pixels mostly of the line's colour (its edges are antialiased).
    let near = |rgba: &[u8], c: [u8; 3]| {
        rgba.chunks(4)
            .filter(|p| (0..3).all(|k| p[k].abs_diff(c[k]) < 60))
            .count()
    };
    let plain = render(&[]);
    let green = render(&["--cell=#00ff00"]);
    assert_eq!(near(&plain, [0, 255, 0]), 0);
    assert!(
        near(&green, [0, 255, 0]) > 60,
        "{}",
        near(&green, [0, 255, 0])
    );
    // Default: dark grey on the white background.
    let grey = render(&["--cell"]);
    assert!(near(&grey, [51, 51, 51]) > near(&plain, [51, 51, 51]) + 60);
    let e = fails(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--mode",
        "sndf",
        "--cell",
    ]);
    assert!(e.contains("--cell has no effect with --mode sndf"), "{e}");
    let e = fails(&["render", s(&file), "-o", s(&png), "--cell=nocolour"]);
    assert!(e.contains("--cell \"nocolour\""), "{e}");
    // The colour takes `=`: a file after a bare --cell is the file.
    ok(&[
        "render",
        "-o",
        s(&png),
        "--width",
        "32",
        "--height",
        "24",
        "--cell",
        s(&file),
    ]);
    // A colour there (the old `--cell red`) is named as one.
    let e = fails(&["render", "-o", s(&png), "--cell", "red"]);
    assert!(
        e.contains("red: no such file; is it --cell's colour? A colour goes with `=`: --cell=red"),
        "{e}"
    );
    // An XYZ file without a lattice has no cell.
    let xyz = dir.path().join("a.xyz");
    std::fs::write(&xyz, "2\nno lattice\nAr 0 0 0\nAr 3 0 0\n").unwrap();
    let bare = dir.path().join("a.mdlod");
    ok(&["convert", s(&xyz), "-o", s(&bare)]);
    let out = ok(&[
        "render",
        s(&bare),
        "-o",
        s(&png),
        "--width",
        "32",
        "--height",
        "24",
        "--cell",
    ]);
    assert!(out.contains("records no simulation cell"), "{out}");

    // A cell much larger than its atoms: with --cell the fit frames the whole cell (every
    // edge inside the image, its depth range too), without it the atoms fill the image.
    let xyz = dir.path().join("vacuum.xyz");
    let mut text = String::from("27\nLattice=\"100 0 0 0 100 0 0 0 100\"\n");
    for i in 0..27 {
        let (x, y, z) = (i % 3, i / 3 % 3, i / 9);
        text += &format!("Ar {} {} {}\n", 10 + 3 * x, 10 + 3 * y, 10 + 3 * z);
    }
    std::fs::write(&xyz, text).unwrap();
    let vacuum = dir.path().join("vacuum.mdlod");
    ok(&["convert", s(&xyz), "-o", s(&vacuum)]);
    let (w, h) = (120u32, 90u32);
    let drawn = |extra: &[&str]| {
        let mut args = vec!["render", s(&vacuum), "-o", s(&png), "--width", "120"];
        args.extend(["--height", "90", "--background", "#000000"]);
        args.extend_from_slice(extra);
        ok(&args);
        let px = read_png(&png).2;
        // The columns and rows of pixels drawn (any channel above 40).
        let on = |x: u32, y: u32| px[4 * (y * w + x) as usize..][..3].iter().any(|&v| v > 40);
        let cols: Vec<u32> = (0..w).filter(|&x| (0..h).any(|y| on(x, y))).collect();
        let rows: Vec<u32> = (0..h).filter(|&y| (0..w).any(|x| on(x, y))).collect();
        (cols[0], cols[cols.len() - 1], rows[0], rows[rows.len() - 1])
    };
    let (x0, x1, y0, y1) = drawn(&["--cell=#ffffff"]);
    assert!(
        x0 >= 2 && x1 < w - 2 && y0 >= 2 && y1 < h - 2,
        "{x0} {x1} {y0} {y1}"
    );
    // The cell spans nearly the image's height (its 12 edges all drawn).
    assert!(y1 - y0 > h * 3 / 4, "{y0} {y1}");
    let (_, _, y0, y1) = drawn(&[]);
    assert!(
        y1 - y0 > h * 3 / 5,
        "the atoms alone span rows {y0} to {y1}"
    );
}

/// `--target X,Y,Z` pans: the camera looks at that point from the fitted distance (the
/// saved view says so), alone or changing a view file's target.
#[test]
fn a_target_pans_the_view() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("a.mdlod");
    ok(&[
        "convert",
        s(&lammps_sample_path("cuag_alloy.unwrapped.dump")),
        "-o",
        s(&file),
    ]);
    let png = dir.path().join("a.png");
    let view = |extra: &[&str]| {
        let saved = dir.path().join("v.json");
        let mut args = vec![
            "render",
            s(&file),
            "-o",
            s(&png),
            "--width",
            "48",
            "--height",
            "32",
            "--save-view",
            s(&saved),
        ];
        args.extend_from_slice(extra);
        ok(&args);
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&saved).unwrap()).unwrap();
        let t: Vec<f64> = v["target"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        (t, v["distance"].as_f64().unwrap(), read_png(&png).2)
    };
    let (centre, distance, whole) = view(&[]);
    let (t, d, panned) = view(&["--target", "1.5,-2,3"]);
    assert_eq!(t, [1.5, -2.0, 3.0]);
    assert!((d - distance).abs() < 1e-3 * distance, "{d} {distance}");
    assert_ne!(panned, whole);
    assert_ne!(centre, t);
    // With a view file: its target replaced, its distance kept.
    let saved = dir.path().join("keep.json");
    ok(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--width",
        "48",
        "--height",
        "32",
        "--zoom",
        "2",
        "--save-view",
        s(&saved),
    ]);
    let (t, d, _) = view(&["--view", s(&saved), "--target", "0,0,0"]);
    assert_eq!(t, [0.0, 0.0, 0.0]);
    assert!(
        (d - distance / 2.0).abs() < 1e-3 * distance,
        "{d} {distance}"
    );
    // Looking away from the data draws nothing, and says so.
    let far = ok(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--width",
        "48",
        "--height",
        "32",
        "--target",
        "10000,0,0",
    ]);
    assert!(
        far.contains("nothing is drawn: none of the data is in view"),
        "{far}"
    );
    let e = fails(&["render", s(&file), "-o", s(&png), "--target", "1,nan,2"]);
    assert!(e.contains("a point needs finite numbers"), "{e}");
}

/// `info` counts each species' particles (the GSD sample's companion XYZ files hold 143
/// of type A and 157 of B), in text and JSON.
#[test]
fn info_counts_the_particles_of_each_species() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("g.mdlod");
    let gsd = mdlod_datasets::gsd_sample_path("hoomd_mixture.gsd");
    ok(&["convert", s(&gsd), "-o", s(&file)]);
    let text = ok(&["info", s(&file)]);
    assert!(
        text.contains("143 particles") && text.contains("157 particles"),
        "{text}"
    );
    let json: serde_json::Value = serde_json::from_str(&ok(&["info", "--json", s(&file)])).unwrap();
    let counts: Vec<u64> = json["species"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["count"].as_u64().unwrap())
        .collect();
    assert_eq!(counts, [143, 157]);
}

/// Hidden species leave the clusters too: at a coarse error, no pixel takes a hidden
/// species' colour (mixed clusters are refined until they hold none). Clusters recoloured
/// only approximately (more than four species) are reported.
#[test]
fn hidden_species_leave_the_clusters_and_inexact_recolouring_is_reported() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("a.lammpstrj");
    generate(&["alloy", "-n", "20000"], &dump);
    let file = dir.path().join("a.mdlod");
    ok(&["convert", s(&dump), "-o", s(&file)]);
    let png = dir.path().join("a.png");
    let render = |extra: &[&str]| {
        let mut args = vec!["render", s(&file), "-o", s(&png)];
        args.extend(["--width", "64", "--height", "48", "--screen-error", "12"]);
        args.extend([
            "--species-colour",
            "1=#ff0000",
            "--species-colour",
            "2=#0000ff",
        ]);
        args.extend(extra);
        let out = ok(&args);
        let (_, _, px) = read_png(&png);
        let red = px
            .chunks(4)
            .filter(|p| p[0] > p[1].saturating_add(8))
            .count();
        (out, red)
    };
    let (out, red) = render(&[]);
    assert!(red > 0 && out.contains("cluster spheres"), "{out}");
    // Copper (type 1) hidden: the silver spheres alone, blue (white highlights only).
    let (out, red) = render(&["--hide-species", "1"]);
    assert_eq!(red, 0, "{out}");
    assert!(!out.contains("approximately"), "{out}");
    // Six labelled species, one restyled: the clusters' new colours are a fit.
    let xyz = dir.path().join("six.xyz");
    let mut text = String::from("30000\nsix\n");
    for i in 0..30000u32 {
        let x = |k: u32| (i.wrapping_mul(2654435761 + k) % 10007) as f32 / 100.0;
        text += &format!(
            "{} {} {} {}\n",
            ["A", "Q", "R", "T", "X", "Z"][i as usize % 6],
            x(0),
            x(7),
            x(13)
        );
    }
    std::fs::write(&xyz, text).unwrap();
    let six = dir.path().join("six.mdlod");
    ok(&["convert", s(&xyz), "-o", s(&six)]);
    let args = [
        "render",
        s(&six),
        "-o",
        s(&png),
        "--width",
        "64",
        "--height",
        "48",
    ];
    let out = ok(&[
        &args[..],
        &["--species-colour", "Q=#0000ff", "--screen-error", "30"],
    ]
    .concat());
    assert!(
        out.contains("approximately") && out.contains("the 6 species"),
        "{out}"
    );
    // At error 0 no cluster is drawn: nothing to say.
    let out = ok(&[
        &args[..],
        &["--species-colour", "Q=#0000ff", "--screen-error", "0"],
    ]
    .concat());
    assert!(!out.contains("approximately"), "{out}");
}

/// An XYZ timestep written as a float is read (`Timestep=1e2`); one that is no whole
/// number is said, the frame numbered by its position.
#[test]
fn xyz_timesteps_that_are_no_whole_numbers_are_said() {
    let dir = tempfile::tempdir().unwrap();
    let xyz = dir.path().join("ts.xyz");
    let mut text = String::new();
    for t in ["0", "x", "1e2"] {
        text.push_str(&format!(
            "2\nProperties=species:S:1:pos:R:3 Timestep={t}\nCu 0 0 0\nCu 3 0 0\n"
        ));
    }
    std::fs::write(&xyz, text).unwrap();
    let d = dir.path().join("ts.d");
    let out = ok(&["batch", s(&xyz), "-o", s(&d)]);
    assert!(
        out.contains("frame 1's comment line gives `Timestep=x`, no whole number: the frame is numbered by its position, 1"),
        "{out}"
    );
    for name in ["frame-0.mdlod", "frame-1.mdlod", "frame-100.mdlod"] {
        assert!(d.join(name).exists(), "{name}");
    }
}

/// A last frame with two atom lines run together (a line of twice the columns, the file
/// ending whole) is damage, not a run still writing: `convert` and `batch` name the line
/// and fail, instead of leaving the frame out as one to convert later.
#[test]
fn a_last_frame_with_lines_run_together_is_an_error_not_a_frame_cut_short() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("t.lammpstrj");
    generate(&["droplets", "-n", "2000", "--frames", "3"], &dump);
    let mut text = std::fs::read(&dump).unwrap();
    // The newline before the last atom line becomes a space.
    let last = text[..text.len() - 1]
        .iter()
        .rposition(|&b| b == b'\n')
        .unwrap();
    text[last] = b' ';
    std::fs::write(&dump, &text).unwrap();
    let lines = text.iter().filter(|&&b| b == b'\n').count();
    let out_file = dir.path().join("t.mdlod");
    let err = fails(&["convert", s(&dump), "-o", s(&out_file)]);
    assert!(
        err.contains(&format!("t.lammpstrj:{lines}: expected")) && err.contains("columns, found"),
        "{err}"
    );
    assert!(!out_file.exists());
    let d = dir.path().join("t.d");
    let run = mdlod(&["batch", s(&dump), "-o", s(&d)]);
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        !run.status.success() && err.contains("columns, found"),
        "{err}"
    );
}

/// A dump whose last frames hold no particles (a hopper discharged, a pour not started):
/// `convert` converts the last frame with particles with a note; `--last` and
/// `--frame -1` refuse, naming it; an input with no particles at all says so.
#[test]
fn a_dump_ending_in_empty_frames_converts_its_last_frame_with_particles() {
    let dir = tempfile::tempdir().unwrap();
    let frame = |t: u64, n: usize| {
        let mut s = format!(
            "ITEM: TIMESTEP\n{t}\nITEM: NUMBER OF ATOMS\n{n}\nITEM: BOX BOUNDS pp pp ff\n\
             0 10\n0 10\n0 10\nITEM: ATOMS id type x y z\n"
        );
        for i in 0..n {
            s += &format!("{} 1 {}.5 {}.5 0.5\n", i + 1, i % 10, i / 10);
        }
        s
    };
    let dump = dir.path().join("hopper.lammpstrj");
    std::fs::write(
        &dump,
        frame(0, 50) + &frame(100, 20) + &frame(200, 0) + &frame(300, 0),
    )
    .unwrap();
    let out_file = dir.path().join("h.mdlod");
    let out = ok(&["convert", s(&dump), "-o", s(&out_file)]);
    assert!(
        out.contains(
            "note: the last 2 frames (from frame 2) hold no particles: converting frame 1 \
             (timestep 100), the last with particles"
        ) && out.contains("(frame 1 of 4, counted from 0)"),
        "{out}"
    );
    let file = MdlodFile::open(&out_file).unwrap();
    assert_eq!(
        (file.particle_count(), file.metadata().timestep),
        (20, Some(100))
    );
    for last in [&["--last"][..], &["--frame", "-1"]] {
        let err = fails(&[&["convert", s(&dump), "-o", s(&out_file)], last].concat());
        assert!(
            err.contains(
                "frame 3 (timestep 300): no particles, and a .mdlod file needs at least one; \
                 the last frame with particles is frame 1 (timestep 100): --frame 1 converts it"
            ),
            "{err}"
        );
    }
    let empty = dir.path().join("empty.lammpstrj");
    std::fs::write(&empty, frame(0, 0) + &frame(100, 0)).unwrap();
    let err = fails(&["convert", s(&empty), "-o", s(&out_file)]);
    assert!(
        err.contains("frame 1 (timestep 100): no particles")
            && err.contains("no frame of the input holds particles"),
        "{err}"
    );
}

/// A dump whose last frame is cut short (a run still writing): `convert` converts the
/// frame before it with a note (`--last` refuses, saying which frame converts); `batch`
/// converts the others, leaves the cut frame out of the
/// manifest and its expected count (the directory verifies), says so, and converts it
/// once the dump is complete. A frame cut short that is not its input's last fails.
#[test]
fn a_dump_cut_in_its_last_frame_names_what_converts() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("t.lammpstrj");
    generate(&["droplets", "-n", "2000", "--frames", "3"], &dump);
    let text = std::fs::read(&dump).unwrap();
    // Cut after a whole atom line (one cut inside a line is the next test's).
    let cut = text[..text.len() - 20_000]
        .iter()
        .rposition(|&b| b == b'\n')
        .unwrap()
        + 1;
    std::fs::write(&dump, &text[..cut]).unwrap();
    let out_file = dir.path().join("t.mdlod");
    let err = fails(&["convert", s(&dump), "-o", s(&out_file), "--last"]);
    assert!(
        err.contains("truncated frame") && err.contains("--frame 1 converts the last complete"),
        "{err}"
    );
    let run = mdlod(&["convert", s(&dump), "-o", s(&out_file)]);
    let (out, note) = (
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr),
    );
    assert!(run.status.success(), "{note}");
    assert!(
        out.contains(
            "the last frame (2) is incomplete (a run still writing it?): converting frame 1"
        ),
        "{out}"
    );
    assert!(out.contains("(frame 1 of 3, counted from 0)"), "{out}");
    assert_eq!(
        MdlodFile::open(&out_file).unwrap().metadata().timestep,
        Some(100)
    );
    let d = dir.path().join("t.d");
    let out = ok(&["batch", s(&dump), "-o", s(&d)]);
    assert!(
        out.contains("frame 2 (timestep 200), the input's last, is cut short")
            && out.contains("truncated frame")
            && out.contains("2 converted, 0 already done, 1 cut short and left for a rerun"),
        "{out}"
    );
    let manifest = mdlod_preprocess::batch::read_manifest(&d).unwrap();
    assert_eq!(manifest.frames.len(), 2);
    assert_eq!(manifest.expected_frames, Some(2));
    ok(&["verify", s(&d)]);
    let again = ok(&["batch", s(&dump), "-o", s(&d)]);
    assert!(
        again.contains("0 converted, 2 already done, 1 cut short"),
        "{again}"
    );
    // Complete now: the last frame is converted, the two before it kept (the dump
    // changed, their bytes did not).
    std::fs::write(&dump, &text).unwrap();
    let done = ok(&["batch", s(&dump), "-o", s(&d)]);
    assert!(!done.contains("cut short"), "{done}");
    assert!(
        done.contains(
            "2 frames of inputs changed since their conversion (appended to, touched or copied) \
             still hold the same bytes: kept"
        ) && done.contains("1 converted, 2 already done")
            && !done.contains("converted again"),
        "{done}"
    );
    assert_eq!(batch_frames(&d).len(), 3);
    ok(&["verify", s(&d)]);
    // Cut in a frame before the last (lines lost in the middle): an error.
    let lines: Vec<&str> = std::str::from_utf8(&text).unwrap().lines().collect();
    let second = lines
        .iter()
        .enumerate()
        .filter(|(_, l)| l.starts_with("ITEM: TIMESTEP"))
        .nth(1)
        .unwrap()
        .0;
    let mut cut: Vec<&str> = lines.clone();
    cut.drain(second - 100..second);
    std::fs::write(&dump, cut.join("\n") + "\n").unwrap();
    let d2 = dir.path().join("t2.d");
    let err = fails(&["batch", s(&dump), "-o", s(&d2)]);
    assert!(
        err.contains("truncated frame") && err.contains("of the 3 frames to convert"),
        "{err}"
    );
}

/// A movie of a trajectory whose species come and go: a style may name a species some
/// frames lack (it applies where present); one no frame has is an error listing them.
#[test]
fn a_movie_styles_species_that_only_some_frames_hold() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("a.lammpstrj");
    generate(&["alloy", "-n", "2000", "--frames", "2"], &dump);
    // The first frame: type 1 only.
    let edited = edit_atoms(&dump, |frame, f| {
        if frame == 0 {
            f[1] = "1".into();
        }
    });
    std::fs::write(&dump, edited).unwrap();
    let d = dir.path().join("a.d");
    ok(&["batch", s(&dump), "-o", s(&d)]);
    let first = mdlod_preprocess::batch::read_manifest(&d).unwrap().frames[0]
        .file
        .clone();
    let info = ok(&["info", s(&d.join(first))]);
    assert!(!info.contains("species      2"), "{info}");
    let pattern = dir.path().join("m-%02d.png");
    let size = ["--width", "32", "--height", "24"];
    // Species 2 is red where it is, and only there (with the copper around it hidden).
    let mut args = vec![
        "render",
        s(&d),
        "-o",
        s(&pattern),
        "--species-colour",
        "2=#ff0000",
        "--hide-species",
        "1",
        "--screen-error",
        "0",
    ];
    args.extend(size);
    let out = ok(&args);
    assert!(out.contains("rendered 2 frames"), "{out}");
    let red = |i: usize| {
        let (_, _, px) = read_png(&dir.path().join(format!("m-{i:02}.png")));
        px.chunks(4)
            .filter(|p| p[0] > 200 && p[1] < 60 && p[2] < 60)
            .count()
    };
    assert_eq!(red(0), 0);
    assert!(red(1) > 0);
    let mut args = vec![
        "render",
        s(&d),
        "-o",
        s(&pattern),
        "--species-colour",
        "9=#ff0000",
    ];
    args.extend(size);
    let err = fails(&args);
    assert!(
        err.contains("no frame") && err.contains("\"9\"") && err.contains("1, 2"),
        "{err}"
    );
}

/// With no display (a cluster node, ssh without forwarding) the viewer says what to do,
/// not where in the window toolkit's source it failed.
#[test]
fn the_viewer_without_a_display_says_what_to_do() {
    let dir = tempfile::tempdir().unwrap();
    let frame = converted(dir.path(), "cu_melt.custom.dump");
    let run = Command::new(env!("CARGO_BIN_EXE_mdlod"))
        .args(["view", s(&frame)])
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{err}");
    assert!(
        err.contains("no display") && err.contains("xvfb-run") && !err.contains(".rs:"),
        "{err}"
    );
}

/// `verify DIR` checks a batch directory's frames against its manifest, and fails naming
/// a frame that is not the one listed.
#[test]
fn verify_checks_a_batch_directory() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("d");
    ok(&[
        "batch",
        s(&lammps_sample_path("cu_melt.custom.dump")),
        "-o",
        s(&out),
    ]);
    // The directory or its manifest, as `info` takes them.
    for what in [out.clone(), out.join("dataset.json")] {
        let text = ok(&["verify", s(&what)]);
        assert!(
            text.contains("ok: 6 frames verified against dataset.json"),
            "{text}"
        );
    }
    // A movie of the manifest is the directory's: every frame, numbered.
    let movie = dir.path().join("m-%d.png");
    let manifest = out.join("dataset.json");
    let mut args = vec!["render", s(&manifest), "-o", s(&movie)];
    args.extend(["--width", "64", "--height", "48"]);
    ok(&args);
    assert!((0..6).all(|k| dir.path().join(format!("m-{k}.png")).is_file()));
    // `info` of the directory (or its manifest): the trajectory.
    for what in [out.clone(), out.join("dataset.json")] {
        let text = ok(&["info", s(&what)]);
        assert!(
            text.contains("frames       6 (timesteps 0 to 500, every 100)")
                && text.contains("times        0 to 1")
                && text.contains("particles    500 per frame")
                && text.contains("species      1 (of any frame)"),
            "{text}"
        );
    }
    let json: serde_json::Value = serde_json::from_str(&ok(&["info", s(&out), "--json"])).unwrap();
    assert_eq!(json["frames"], 6);
    assert_eq!(json["timesteps"], serde_json::json!([0, 500]));
    // A manifest listing a timestep twice (edited by hand): said, not read as an
    // interval of 0.
    let manifest_text = std::fs::read_to_string(&manifest).unwrap();
    let mut edited: serde_json::Value = serde_json::from_str(&manifest_text).unwrap();
    let first = edited["frames"][0].clone();
    edited["frames"].as_array_mut().unwrap().push(first);
    std::fs::write(&manifest, edited.to_string()).unwrap();
    let text = ok(&["info", s(&out)]);
    assert!(
        text.contains("1 frame repeats a timestep listed before") && !text.contains("every 0"),
        "{text}"
    );
    std::fs::write(&manifest, manifest_text).unwrap();
    let m = mdlod_preprocess::batch::read_manifest(&out).unwrap();
    // A frame damaged on disk (one byte of its data flipped): verify finds it and says
    // how to have it converted again, as a rerun trusts a frame that opens.
    let damaged = out.join(&m.frames[2].file);
    let mut bytes = std::fs::read(&damaged).unwrap();
    let middle = bytes.len() / 2;
    bytes[middle] ^= 0xff;
    std::fs::write(&damaged, bytes).unwrap();
    let said = {
        let o = mdlod(&["verify", s(&out)]);
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    assert!(
        said.contains("delete it and rerun the batch, which converts it again"),
        "{said}"
    );
    std::fs::remove_file(&damaged).unwrap();
    ok(&[
        "batch",
        s(&lammps_sample_path("cu_melt.custom.dump")),
        "-o",
        s(&out),
    ]);
    ok(&["verify", s(&out)]);
    std::fs::copy(out.join(&m.frames[0].file), out.join(&m.frames[1].file)).unwrap();
    let err = fails(&["verify", s(&out)]);
    assert!(err.contains("1 problem (5 frames verified)"), "{err}");
    // A sharded run: the shards that wrote no manifest are named, the first few of a
    // count read from a file name, however large.
    let sharded = dir.path().join("s");
    let dump = lammps_sample_path("cu_melt.custom.dump");
    ok(&["batch", s(&dump), "-o", s(&sharded), "--shard", "0/3"]);
    // The problems are listed on standard output, the count in the error.
    let problems = |dir: &Path| {
        let out = mdlod(&["verify", s(dir)]);
        assert!(!out.status.success());
        String::from_utf8(out.stdout).unwrap() + &String::from_utf8(out.stderr).unwrap()
    };
    let err = problems(&sharded);
    assert!(err.contains("shards 1, 2 of 3 wrote no manifest"), "{err}");
    let lone = sharded.join("dataset.shard-0-of-3.json");
    std::fs::rename(&lone, sharded.join("dataset.shard-0-of-4000000000.json")).unwrap();
    let err = problems(&sharded);
    assert!(!err.contains("panicked"), "{err}");
    assert!(
        err.contains("shards 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, and 3999999989 more of 4000000000"),
        "{err}"
    );
}

/// A count that cannot fit on the disk is refused before anything is written (a typo of
/// a few digits filled the disk before failing).
#[test]
fn generate_refuses_data_the_disk_cannot_hold() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("huge.lammpstrj");
    let err = fails(&[
        "generate",
        "crater",
        "-n",
        "1000000000000000",
        "-o",
        s(&out),
    ]);
    assert!(
        err.contains("need about 3.600e7 GB") && err.contains(" free in "),
        "{err}"
    );
    assert!(!out.exists());
}

/// `--species-name` gives numbered LAMMPS types their elements' looks: the file names
/// them by element, `--radius` and render's `--hide-species` take the new names, two
/// types given one name are one species, and a batch converts a frame again when the
/// renames change (and skips it when they do not).
#[test]
fn species_names_give_numbered_types_their_elements() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("a.lammpstrj");
    // Copper (type 1) and silver (type 2), by number only.
    generate(&["alloy", "-n", "2000", "--frames", "2"], &input);
    let out = dir.path().join("a.mdlod");
    let species = |p: &Path| -> Vec<(String, f32)> {
        let f = MdlodFile::open(p).unwrap();
        f.metadata()
            .species
            .iter()
            .map(|s| (s.name.clone(), s.radius))
            .collect()
    };
    let cu = mdlod_preprocess::species::element("Cu").unwrap().0;
    ok(&[
        "convert",
        s(&input),
        "-o",
        s(&out),
        "--species-name",
        "1=Cu",
        "--species-name",
        "2=Ag",
        "--radius",
        "Ag=1.5",
    ]);
    assert_eq!(
        species(&out),
        [("Cu".to_string(), cu), ("Ag".to_string(), 1.5)]
    );
    let info = ok(&["info", s(&out)]);
    assert!(info.contains("Cu") && info.contains("Ag"), "{info}");
    // Both types one species.
    ok(&[
        "convert",
        s(&input),
        "-o",
        s(&out),
        "--species-name",
        "1=M",
        "--species-name",
        "2=M",
    ]);
    assert_eq!(species(&out).len(), 1);
    assert_eq!(MdlodFile::open(&out).unwrap().particle_count(), 2000);
    // A type the input lacks, and a radius by the old number, are errors.
    let err = fails(&["convert", s(&input), "-o", s(&out), "--species-name", "3=O"]);
    assert!(
        err.contains("--species-name 3=O: no species named \"3\"") && err.contains("named 1, 2"),
        "{err}"
    );
    let err = fails(&[
        "convert",
        s(&input),
        "-o",
        s(&out),
        "--species-name",
        "1=Cu",
        "--radius",
        "1=1.3",
    ]);
    assert!(
        err.contains("--species-name renamed \"1\" to \"Cu\", and --radius takes the new name: --radius Cu=1.3"),
        "{err}"
    );
    let err = fails(&["convert", s(&input), "-o", s(&out), "--species-name", "1"]);
    assert!(err.contains("expected NAME=NEW_NAME"), "{err}");
    // Without renames, a radius by element says how to name the type.
    let err = fails(&["convert", s(&input), "-o", s(&out), "--radius", "Cu=1.3"]);
    assert!(err.contains("--species-name 1=Cu --radius Cu=1.3"), "{err}");

    // A batch records the renames: the same ones skip finished frames, others redo them.
    let d = dir.path().join("d");
    let renames = ["--species-name", "1=Cu", "--species-name", "2=Ag"];
    let batch = |extra: &[&str]| {
        let mut args = vec!["batch", s(&input), "-o", s(&d)];
        args.extend(extra);
        ok(&args)
    };
    batch(&renames);
    let frames = batch_frames(&d);
    assert_eq!(frames.len(), 2);
    for f in &frames {
        assert_eq!(species(&d.join(f))[0], ("Cu".to_string(), cu));
    }
    let again = batch(&renames);
    assert!(again.contains("0 converted, 2 already done"), "{again}");
    let redone = batch(&[]);
    assert!(
        redone.contains(
            "note: 2 frames already converted were converted again: 2 built with other \
             settings (--species-name)"
        ),
        "{redone}"
    );
    for f in &frames {
        assert_eq!(species(&d.join(f))[0].0, "1", "{f}: converted again");
    }
    // A rename no frame's species has is an error at the end.
    let mut args = vec!["batch", s(&input), "-o", s(&d)];
    args.extend(["--species-name", "7=O"]);
    let err = fails(&args);
    assert!(err.contains("--species-name 7=O"), "{err}");
}

/// Inputs no reader can index and outputs a conversion must not replace are refused
/// before anything is read or written.
#[test]
fn convert_refuses_streams_and_replacing_other_files() {
    let dir = tempfile::tempdir().unwrap();
    let input = lammps_sample_path("cu_melt.custom.dump");
    // A file that is no .mdlod file named as the output stays as it was; an image's
    // name is refused whether it exists or not.
    let notes = dir.path().join("notes.txt");
    std::fs::write(&notes, b"keep me").unwrap();
    let err = fails(&["convert", s(&input), "-o", s(&notes)]);
    assert!(
        err.contains("notes.txt: exists and is no .mdlod file"),
        "{err}"
    );
    assert_eq!(std::fs::read(&notes).unwrap(), b"keep me");
    let png = dir.path().join("picture.png");
    std::fs::write(&png, b"\x89PNG\r\n\x1a\n not really").unwrap();
    let err = fails(&["convert", s(&input), "-o", s(&png)]);
    assert!(
        err.contains("picture.png: convert writes a .mdlod file, not an image"),
        "{err}"
    );
    assert_eq!(
        std::fs::read(&png).unwrap(),
        b"\x89PNG\r\n\x1a\n not really"
    );
    // An earlier .mdlod file is replaced.
    let out = dir.path().join("a.mdlod");
    ok(&["convert", s(&input), "-o", s(&out)]);
    ok(&["convert", s(&input), "-o", s(&out), "--frame", "0"]);
    // Standard input and pipes: the reader would see an empty file.
    let err = fails(&["convert", "-", "-o", s(&out)]);
    assert!(err.contains("standard input is not supported"), "{err}");
    let fifo = dir.path().join("pipe.lammpstrj");
    let made = Command::new("mkfifo").arg(&fifo).status();
    if made.is_ok_and(|st| st.success()) {
        let err = fails(&["convert", s(&fifo), "-o", s(&out)]);
        assert!(err.contains("is a pipe or device, not a file"), "{err}");
        let err = fails(&["batch", s(&fifo), "-o", s(&dir.path().join("d"))]);
        assert!(err.contains("is a pipe or device, not a file"), "{err}");
    }
}

/// A memory limit below what one chunk needs says both ways out: the limit a chunk
/// needs, and the chunk size within the limit (which then converts).
#[test]
fn a_limit_below_a_chunk_names_the_chunk_size_that_fits() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("c.lammpstrj");
    generate(&["crater", "-n", "20000"], &input);
    let out = dir.path().join("c.mdlod");
    let args = |chunk: &'static str| {
        let mut a = vec!["convert", s(&input), "-o", s(&out)];
        a.extend(["--memory-limit", "65M", "--chunk-points", chunk]);
        a
    };
    let err = fails(&args("10000"));
    let fit = err
        .split("lower --chunk-points to ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .unwrap_or_else(|| panic!("{err}"));
    assert!(err.contains("raise --memory-limit to at least"), "{err}");
    let fit: &'static str = Box::leak(fit.to_string().into_boxed_str());
    ok(&args(fit));
    assert_eq!(MdlodFile::open(&out).unwrap().particle_count(), 20000);
}

/// A shrink-wrapped cell stretched by a lost atom is drawn with `--cell` but not fitted:
/// the view frames the material, as without the cell (it framed the cell, 100 times the
/// material's height, and the material was a few pixels); a cell the data does not
/// stretch (vacuum above a slab) is fitted whole.
#[test]
fn a_cell_stretched_by_a_lost_atom_is_drawn_but_not_fitted() {
    let dir = tempfile::tempdir().unwrap();
    let dump = |top: f64, lost: bool| {
        let mut text = format!(
            "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n500\nITEM: BOX BOUNDS pp pp ss\n0 30\n\
             0 30\n0 {top}\nITEM: ATOMS id type x y z\n"
        );
        for i in 0..500 {
            let z = if lost && i == 499 {
                top
            } else {
                f64::from(i / 100 * 3)
            };
            text += &format!("{} 1 {} {} {z}\n", i + 1, (i % 10) * 3, (i / 10 % 10) * 3);
        }
        text
    };
    let distance = |text: String, cell: bool| -> f64 {
        let input = dir.path().join("d.lammpstrj");
        std::fs::write(&input, text).unwrap();
        let file = dir.path().join("d.mdlod");
        ok(&["convert", s(&input), "-o", s(&file), "--radius", "1=1.28"]);
        let view = dir.path().join("v.json");
        let png = dir.path().join("p.png");
        let mut args = vec!["render", s(&file), "-o", s(&png), "--save-view", s(&view)];
        args.extend(["--width", "64", "--height", "48"]);
        if cell {
            args.push("--cell");
        }
        ok(&args);
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&view).unwrap()).unwrap();
        v["distance"].as_f64().unwrap()
    };
    let (with, without) = (
        distance(dump(3000.0, true), true),
        distance(dump(3000.0, true), false),
    );
    assert!(with < 1.2 * without, "{with} against {without}");
    // Vacuum above a slab, no atom in it: the cell is framed whole.
    let (with, without) = (
        distance(dump(300.0, false), true),
        distance(dump(300.0, false), false),
    );
    assert!(with > 3.0 * without, "{with} against {without}");
}

/// Positions that will not draw as the user expects are noted at conversion: an atom
/// lost far outside the box (whole and chunked builds), and coordinates so far from the
/// origin that single precision snaps them to a grid coarser than the particles.
#[test]
fn lost_atoms_and_coordinates_beyond_single_precision_are_noted() {
    let dir = tempfile::tempdir().unwrap();
    let far = dir.path().join("far.lammpstrj");
    let mut text = String::from(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n500\nITEM: BOX BOUNDS pp pp pp\n0 30\n\
         0 30\n0 30\nITEM: ATOMS id type x y z\n",
    );
    for i in 0..500 {
        let x = if i == 499 {
            3000.0
        } else {
            (i % 10) as f64 * 3.0
        };
        text += &format!("{} 1 {x} {} {}\n", i + 1, (i / 10 % 10) * 3, i / 100 * 3);
    }
    std::fs::write(&far, text).unwrap();
    let out = dir.path().join("far.mdlod");
    let whole = ok(&["convert", s(&far), "-o", s(&out)]);
    assert!(
        whole.contains("note: 1 particle lies more than 10 box lengths outside the box")
            && whole.contains("the farthest at (3000, 27, 12)"),
        "{whole}"
    );
    let mut args = vec!["convert", s(&far), "-o", s(&out)];
    args.extend(["--chunk-points", "100", "--root-points", "16"]);
    let chunked = ok(&args);
    assert!(
        chunked.contains("note: particles lie more than 10 box lengths outside the box"),
        "{chunked}"
    );
    // Inside the box (the sample's atoms): no note of positions (only that of its types'
    // default radius, and of its column left behind).
    let sample = lammps_sample_path("cu_melt.custom.dump");
    let out_text = ok(&["convert", s(&sample), "-o", s(&out)]);
    assert!(
        out_text
            .lines()
            .filter(|l| l.contains("note:"))
            .all(|l| l.contains("drawn at radius 0.5, the default")
                || l.contains("column c_pe is not kept")),
        "{out_text}"
    );

    // A blob of width 0.05 around 10^5, particles of radius 0.002: f32 keeps steps of
    // 2^-7 there.
    let offset = dir.path().join("offset.xyz");
    let mut text = String::from("300\nProperties=species:S:1:pos:R:3\n");
    for i in 0..300 {
        let d = f64::from(i) * 1.7e-4;
        text += &format!("A {:.9} {:.9} {:.9}\n", 1e5 + d, 1e5 - d, 1e5 + d / 2.0);
    }
    std::fs::write(&offset, text).unwrap();
    let noted = ok(&["convert", s(&offset), "-o", s(&out), "--radius", "A=0.002"]);
    assert!(
        noted.contains("coordinates reach 1.000e5")
            && noted.contains("steps of 7.81e-3")
            && noted.contains("subtract its centre"),
        "{noted}"
    );
    // `info` says so too: the error it shows is measured after the rounding.
    let info = ok(&["info", s(&out)]);
    assert!(
        info.contains("this far from the origin are 7.812e-3 apart")
            && info.contains("rounded to them, by up to 3.906e-3"),
        "{info}"
    );
    let json: serde_json::Value = serde_json::from_str(&ok(&["info", s(&out), "--json"])).unwrap();
    assert_eq!(json["single_precision_spacing"], 0.0078125);
    assert!(!ok(&["info", s(&converted(dir.path(), "cu_melt.xyz"))]).contains("note:"));
    // Particles as large as the steps: no note of them (radii this size overlap into
    // one blob of the 300, which is noted apart).
    let fine = ok(&["convert", s(&offset), "-o", s(&out), "--radius", "A=1"]);
    assert!(!fine.contains("coordinates reach"), "{fine}");
    assert!(
        fine.contains("times the mean spacing of those particles"),
        "{fine}"
    );
    // Particles of their own sizes (smoothing lengths): the smallest particle's radius
    // counts, not the species' mean (one particle of 0.002 among 299 of 1).
    let sized = dir.path().join("sized.xyz");
    let mut text = String::from("300\nProperties=species:S:1:pos:R:3:radius:R:1\n");
    for i in 0..300 {
        let d = f64::from(i) * 1.7e-4;
        let r = if i == 7 { 0.002 } else { 1.0 };
        text += &format!("A {:.9} {:.9} {:.9} {r}\n", 1e5 + d, 1e5 - d, 1e5 + d / 2.0);
    }
    std::fs::write(&sized, text).unwrap();
    let noted = ok(&["convert", s(&sized), "-o", s(&out)]);
    assert!(
        noted.contains("coordinates reach 1.000e5")
            && noted.contains("the smallest radius (0.002)")
            && noted.contains("the smallest particles are finer than single precision resolves"),
        "{noted}"
    );
    // Data in centimetres around the origin with the default radius: no shift helps, the
    // radius is what is out of scale.
    let cgs = dir.path().join("cgs.xyz");
    let mut text = String::from("27\nProperties=species:S:1:pos:R:3\n");
    for i in 0..27 {
        let at = |k: i32| f64::from(k - 1) * 3e21;
        text += &format!("H {:e} {:e} {:e}\n", at(i % 3), at(i / 3 % 3), at(i / 9));
    }
    std::fs::write(&cgs, text).unwrap();
    let noted = ok(&["convert", s(&cgs), "-o", s(&out), "--radius", "H=0.5"]);
    assert!(
        noted.contains("times the smallest radius")
            && noted.contains("give --radius NAME=R in the data's own units")
            && !noted.contains("subtract its centre"),
        "{noted}"
    );
    // One atom lost at 10^30 beside a box of 30: the radius fits the box, the lost atom
    // sets the coordinates' reach (it used to advise another radius).
    let text = std::fs::read_to_string(&far)
        .unwrap()
        .replace("3000 27 12", "1e30 27 12");
    std::fs::write(&far, text).unwrap();
    let noted = ok(&["convert", s(&far), "-o", s(&out), "--radius", "1=1.28"]);
    assert!(
        noted.contains("coordinates reach 1.000e30")
            && noted.contains("particles far outside the box (below): leave them out")
            && noted.contains("1 particle lies more than 10 box lengths outside the box")
            && !noted.contains("give --radius"),
        "{noted}"
    );
}

/// `--frame` counts from the end when negative, and the summary says which frame of
/// how many was converted.
#[test]
fn frames_count_from_the_end_and_the_summary_names_the_frame() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("a.lammpstrj");
    generate(&["alloy", "-n", "500", "--frames", "3"], &input);
    let out = dir.path().join("a.mdlod");
    let timestep = |args: &[&str]| {
        let mut all = vec!["convert", s(&input), "-o", s(&out)];
        all.extend(args);
        let text = ok(&all);
        (text, MdlodFile::open(&out).unwrap().metadata().timestep)
    };
    let (last, t_last) = timestep(&[]);
    assert!(last.contains("(frame 2, the last of 3)"), "{last}");
    assert_eq!(timestep(&["--frame", "-1"]).1, t_last);
    let (second, t_second) = timestep(&["--frame", "-2"]);
    assert!(
        second.contains("(frame 1 of 3, counted from 0)"),
        "{second}"
    );
    assert_eq!(t_second, timestep(&["--frame", "1"]).1);
    assert_ne!(t_second, t_last);
    let err = fails(&["convert", s(&input), "-o", s(&out), "--frame", "-4"]);
    assert!(
        err.contains("frame -4 does not exist; the file has 3 frames"),
        "{err}"
    );
    // A single-frame input says nothing of frames.
    let one = dir.path().join("one.lammpstrj");
    generate(&["alloy", "-n", "500"], &one);
    let text = ok(&["convert", s(&one), "-o", s(&out)]);
    assert!(!text.contains("(frame"), "{text}");
}

/// A view hiding species fits what it shows: a small solute in a large box of solvent,
/// the solvent hidden, fills the image instead of a tenth of it.
#[test]
fn hiding_species_fits_the_view_to_the_species_shown() {
    let dir = tempfile::tempdir().unwrap();
    let xyz = dir.path().join("solvated.xyz");
    let mut atoms = Vec::new();
    // Solvent W on a lattice filling 0..60; solute S in a ball of radius 4 at the centre.
    for i in 0..20 {
        for j in 0..20 {
            for k in 0..20 {
                let p = [i as f32 * 3.0, j as f32 * 3.0, k as f32 * 3.0];
                let r2: f32 = p.iter().map(|v| (v - 30.0).powi(2)).sum();
                if r2 > 25.0 {
                    atoms.push(format!("W {} {} {}", p[0], p[1], p[2]));
                }
            }
        }
    }
    for i in 0..400 {
        let t = i as f32 * 0.7;
        let r = 4.0 * ((i % 20) as f32 / 20.0).sqrt();
        let (x, y, z) = (r * t.cos(), r * t.sin(), 4.0 * ((i as f32 / 400.0) - 0.5));
        atoms.push(format!("S {} {} {}", 30.0 + x, 30.0 + y, 30.0 + z));
    }
    std::fs::write(
        &xyz,
        format!("{}\nsolvated\n{}\n", atoms.len(), atoms.join("\n")),
    )
    .unwrap();
    let file = dir.path().join("s.mdlod");
    ok(&[
        "convert",
        s(&xyz),
        "-o",
        s(&file),
        "--radius",
        "W=1",
        "--radius",
        "S=1",
    ]);
    let png = dir.path().join("s.png");
    // The columns from the first to the last drawn.
    let covered = |extra: &[&str]| {
        let mut args = vec!["render", s(&file), "-o", s(&png), "--width", "64"];
        args.extend(["--height", "64", "--background", "#000000"]);
        args.extend(extra);
        ok(&args);
        let (w, _, px) = read_png(&png);
        let columns: Vec<usize> = (0..w as usize)
            .filter(|x| {
                px.chunks(4 * w as usize)
                    .any(|row| row[4 * x..4 * x + 3] != [0, 0, 0])
            })
            .collect();
        columns.last().map_or(0, |l| l - columns[0] + 1)
    };
    // The flat solute, seen from 20° above its plane, spans most of the width (its
    // box's corners reach past its disc).
    let shown = covered(&["--hide-species", "W"]);
    assert!(shown >= 32, "the solute spans {shown} of 64 columns");
    // Without hiding, the whole box: the solute is inside it, the box spans the image.
    assert!(covered(&[]) >= 48);

    // Silver spheres in a copper block: the clusters holding both are opened, so the fit
    // frames the silver, not the copper around it.
    let dump = dir.path().join("alloy.lammpstrj");
    generate(&["alloy", "-n", "30000"], &dump);
    let alloy = dir.path().join("alloy.mdlod");
    ok(&["convert", s(&dump), "-o", s(&alloy)]);
    let mut args = vec!["render", s(&alloy), "-o", s(&png), "--width", "64"];
    args.extend([
        "--height",
        "64",
        "--background",
        "#000000",
        "--hide-species",
        "1",
    ]);
    ok(&args);
    let (w, _, px) = read_png(&png);
    let rows: Vec<usize> = px
        .chunks(4 * w as usize)
        .enumerate()
        .filter(|(_, row)| row.chunks(4).any(|p| p[..3] != [0, 0, 0]))
        .map(|(y, _)| y)
        .collect();
    let span = rows.last().map_or(0, |l| l - rows[0] + 1);
    // 53 of 64 rows; 49 when mixed clusters were framed whole.
    assert!(
        span >= 52 && rows[0] >= 1 && rows[rows.len() - 1] < 63,
        "{rows:?}"
    );
}

/// Lost atoms far from the material (a non-periodic box's evaporated atoms) are left out
/// of the fitted view, with a note that names the way back; `--fit-all` fits them too
/// and the material shrinks to a few pixels.
#[test]
fn atoms_far_from_the_rest_are_left_out_of_the_fit_with_a_note() {
    let dir = tempfile::tempdir().unwrap();
    let xyz = dir.path().join("lost.xyz");
    let mut atoms = Vec::new();
    for i in 0..14 {
        for j in 0..14 {
            for k in 0..14 {
                atoms.push(format!(
                    "Cu {} {} {}",
                    i as f32 * 2.5,
                    j as f32 * 2.5,
                    k as f32 * 2.5
                ));
            }
        }
    }
    atoms.push("Cu 4000 10 10".into());
    atoms.push("Cu 10 -3000 10".into());
    std::fs::write(
        &xyz,
        format!("{}\nlost\n{}\n", atoms.len(), atoms.join("\n")),
    )
    .unwrap();
    let file = dir.path().join("lost.mdlod");
    ok(&["convert", s(&xyz), "-o", s(&file)]);
    let png = dir.path().join("lost.png");
    let covered_rows = |extra: &[&str]| {
        let mut args = vec!["render", s(&file), "-o", s(&png), "--width", "64"];
        args.extend([
            "--height",
            "64",
            "--background",
            "#000000",
            "--screen-error",
            "0",
        ]);
        args.extend(extra);
        let out = ok(&args);
        let (w, _, px) = read_png(&png);
        let rows: Vec<usize> = px
            .chunks(4 * w as usize)
            .enumerate()
            .filter(|(_, row)| row.chunks(4).any(|p| p[..3] != [0, 0, 0]))
            .map(|(y, _)| y)
            .collect();
        (rows.last().map_or(0, |l| l - rows[0] + 1), out)
    };
    let (rows, out) = covered_rows(&[]);
    assert!(rows >= 32, "the block spans {rows} of 64 rows");
    assert!(
        out.contains("2 particles far from the rest are left out of the view's fit")
            && out.contains("--fit-all"),
        "{out}"
    );
    let (rows, out) = covered_rows(&["--fit-all"]);
    assert!(
        rows < 8,
        "with every atom fitted the block spans {rows} rows"
    );
    assert!(!out.contains("far from the rest"), "{out}");
    // A movie of a batch directory fits its frames alike, with the same note.
    let d = dir.path().join("lost.d");
    ok(&["batch", s(&xyz), "-o", s(&d)]);
    let movie = dir.path().join("m-%d.png");
    let out = ok(&[
        "render",
        s(&d),
        "-o",
        s(&movie),
        "--width",
        "32",
        "--height",
        "32",
    ]);
    assert!(
        out.contains("2 particles (in 1 frame) far from the rest are left out"),
        "{out}"
    );
}

/// A colour map's dark end keeps its levels in the image: per-particle colours go to the
/// GPU as sRGB bytes, so a flat-lit particle shows its map colour within a level. They
/// went as linear bytes, which have 9 levels where sRGB bytes have 51 (below sRGB 0.2):
/// magma's darkest colours came out up to 5 levels off ((0, 0, 0) for (0, 0, 4), (13,
/// 13, 34) for (10, 8, 34)).
#[test]
fn a_colour_maps_dark_end_keeps_its_levels_in_the_image() {
    use mdlod_render::style::ColourMap;
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("m.lammpstrj");
    // 17 big particles in a row, their values 0 to 16: the map at t = 0, 1/16, ... 1.
    let mut text = String::from(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n17\nITEM: BOX BOUNDS ff ff ff\n\
         -1 1\n-1 33\n-1 1\nITEM: ATOMS id type x y z c_t\n",
    );
    // Along y, which runs left to right seen from above at azimuth 0.
    for i in 0..17 {
        text.push_str(&format!("{} 1 0 {} 0 {i}\n", i + 1, 2 * i));
    }
    std::fs::write(&dump, text).unwrap();
    let file = dir.path().join("m.mdlod");
    ok(&[
        "convert",
        s(&dump),
        "-o",
        s(&file),
        "--attribute",
        "c_t",
        "--radius",
        "1=0.9",
    ]);
    let png = dir.path().join("m.png");
    let (w, h) = (340u32, 40u32);
    ok(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--width",
        &w.to_string(),
        "--height",
        &h.to_string(),
        "--ortho",
        "--elevation",
        "90",
        "--azimuth",
        "0",
        "--colour-map",
        "magma",
        "--attribute-range",
        "0:16",
        "--ambient",
        "1",
        "--diffuse",
        "0",
        "--specular",
        "0",
    ]);
    let (pw, ph, px) = read_png(&png);
    assert_eq!((pw, ph), (w, h));
    let srgb = |v: f32| {
        let v = f64::from(v);
        255.0
            * if v <= 0.003_130_8 {
                12.92 * v
            } else {
                1.055 * v.powf(1.0 / 2.4) - 0.055
            }
    };
    // Each particle's centre: the middle of each run of other than background pixels
    // along the image's middle row.
    let row = (h / 2) as usize;
    let pixel = |x: usize| &px[(row * w as usize + x) * 4..][..3];
    let background = pixel(0).to_vec();
    let mut runs = vec![];
    let mut start = None;
    for x in 0..w as usize {
        match (pixel(x) != background.as_slice(), start) {
            (true, None) => start = Some(x),
            (false, Some(a)) => {
                runs.push((a + x - 1) / 2);
                start = None;
            }
            _ => {}
        }
    }
    if let Some(a) = start {
        runs.push((a + w as usize - 1) / 2);
    }
    assert_eq!(
        runs.len(),
        17,
        "particles found along the middle row: {runs:?}"
    );
    let mut worst = 0.0f64;
    for (i, &x) in runs.iter().enumerate() {
        let want = ColourMap::Magma.colour(i as f32 / 16.0).map(srgb);
        let got = pixel(x);
        for c in 0..3 {
            worst = worst.max((f64::from(got[c]) - want[c]).abs());
        }
        assert!(
            (0..3).all(|c| (f64::from(got[c]) - want[c]).abs() <= 1.5),
            "t = {i}/16 at x = {x}: drawn {got:?}, magma {want:?}"
        );
    }
    eprintln!("largest difference from the map: {worst:.2} levels");

    // A near-black species colour on cluster spheres of a one-species file: exactly the
    // colour asked for. It went through the file's 8-bit linear mixture of the old
    // colour and a recolouring that scaled its rounding up: (17, 17, 11) for #101010.
    let grid = dir.path().join("grid.lammpstrj");
    let mut text = String::from(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n3200\nITEM: BOX BOUNDS pp pp pp\n\
         0 80\n0 40\n-1 1\nITEM: ATOMS id type x y z\n",
    );
    for i in 0..3200 {
        text.push_str(&format!("{} 1 {} {} 0\n", i + 1, i % 80, i / 80));
    }
    std::fs::write(&grid, text).unwrap();
    let file = dir.path().join("grid.mdlod");
    ok(&["convert", s(&grid), "-o", s(&file), "--root-points", "16"]);
    // Flat-lit from above, 2 pixels a unit, at a screen error that draws clusters.
    let flat_render = |extra: &[&str]| {
        let mut args = vec!["render", s(&file), "-o", s(&png), "--width", "160"];
        args.extend([
            "--height",
            "80",
            "--ortho",
            "--elevation",
            "90",
            "--ambient",
            "1",
        ]);
        args.extend([
            "--diffuse",
            "0",
            "--brdf",
            "lambert",
            "--screen-error",
            "16",
        ]);
        args.extend(extra);
        ok(&args)
    };
    let out = flat_render(&["--species-colour", "1=#101010"]);
    assert!(out.contains(" 0 particles and "), "{out}");
    let (_, _, px) = read_png(&png);
    let drawn: Vec<&[u8]> = px
        .chunks(4)
        .map(|p| &p[..3])
        .filter(|p| *p != [255, 255, 255])
        .collect();
    assert!(drawn.len() > 500, "{}", drawn.len());
    assert!(
        drawn.iter().all(|p| *p == [16, 16, 16]),
        "{:?}",
        drawn.iter().find(|p| **p != [16, 16, 16])
    );

    // Five species in bands: every cluster of one species in exactly its new colour
    // (the recolouring map fits no five colours: the blue band came out #bb24ff), and
    // with a species hidden the others' clusters too (#101010 came out (17, 17, 11)).
    let bands = dir.path().join("bands.lammpstrj");
    let mut text = String::from(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n3200\nITEM: BOX BOUNDS pp pp pp\n\
         0 80\n0 40\n-1 1\nITEM: ATOMS id type x y z\n",
    );
    for i in 0..3200 {
        text.push_str(&format!(
            "{} {} {} {} 0\n",
            i + 1,
            1 + (i % 80) / 16,
            i % 80,
            i / 80
        ));
    }
    std::fs::write(&bands, text).unwrap();
    ok(&["convert", s(&bands), "-o", s(&file), "--root-points", "16"]);
    let colours = [
        ("1", [16u8, 16, 16]),
        ("2", [255, 255, 255]),
        ("3", [255, 0, 0]),
        ("4", [0, 0, 255]),
        ("5", [0, 255, 0]),
    ];
    for hide in [None, Some("2")] {
        let mut args = vec!["--background", "#808080"];
        let given: Vec<String> = colours
            .iter()
            .map(|(n, c)| format!("{n}=#{:02x}{:02x}{:02x}", c[0], c[1], c[2]))
            .collect();
        for g in &given {
            args.extend(["--species-colour", g.as_str()]);
        }
        if let Some(h) = hide {
            args.extend(["--hide-species", h]);
        }
        let out = flat_render(&args);
        assert!(hide.is_some() || out.contains(" 0 particles and "), "{out}");
        let (_, _, px) = read_png(&png);
        // Each shown band's clusters in its colour exactly (mixed clusters at the
        // bands' borders take mixtures; with a species hidden, those beside it are
        // opened into particles).
        for (name, want) in &colours {
            let exact = px.chunks(4).filter(|p| p[..3] == want[..]).count();
            let shown = Some(*name) != hide;
            assert!(
                (exact > 50) == shown,
                "species {name} (hidden {hide:?}): {exact} pixels of {want:?}"
            );
        }
    }
}

/// The diverging map puts its white at 0 for values of both signs (a velocity, a
/// stress), in one file and throughout a movie, and says so; a range given stays.
#[test]
fn cool_warm_centres_signed_values_on_zero() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("v.lammpstrj");
    let mut text = String::new();
    for (frame, shift) in [(0, 5.0), (100, 3.0)] {
        text.push_str(&format!(
            "ITEM: TIMESTEP\n{frame}\nITEM: NUMBER OF ATOMS\n400\nITEM: BOX BOUNDS pp pp pp\n\
             0 40\n0 40\n0 2\nITEM: ATOMS id type x y z vz\n"
        ));
        for i in 0..400 {
            let (x, y) = ((i % 20) as f32 * 2.0, (i / 20) as f32 * 2.0);
            text.push_str(&format!("{} 1 {x} {y} 1 {}\n", i + 1, x / 2.0 - shift));
        }
    }
    std::fs::write(&dump, text).unwrap();
    let file = dir.path().join("v.mdlod");
    // (The last frame: vz from -3 to 16.)
    ok(&["convert", s(&dump), "-o", s(&file), "--attribute", "vz"]);
    let png = dir.path().join("v.png");
    let render = |extra: &[&str]| {
        let mut args = vec![
            "render",
            s(&file),
            "-o",
            s(&png),
            "--width",
            "40",
            "--height",
            "40",
        ];
        args.extend(["--colour-map", "cool-warm", "--elevation", "90"]);
        args.extend(extra);
        (ok(&args), read_png(&png).2)
    };
    let (out, centred) = render(&[]);
    assert!(
        out.contains(
            "vz from -16 to 16 (centred on 0, the map's white; the file's range is -3 to 16"
        ),
        "{out}"
    );
    let (out, own) = render(&["--attribute-range=-5:14"]);
    assert!(
        out.contains("vz from -5 to 14 (--attribute-range), the map's white at 4.5 (not 0"),
        "{out}"
    );
    assert_ne!(centred, own);
    // Viridis has no middle: the file's range.
    let out = ok(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--width",
        "40",
        "--height",
        "40",
        "--colour-map",
        "viridis",
    ]);
    assert!(out.contains("vz from -3 to 16 (the file's range)"), "{out}");
    // A movie: every frame's range (-5 to 16 over both), centred.
    let d = dir.path().join("v.d");
    ok(&["batch", s(&dump), "-o", s(&d), "--attribute", "vz"]);
    let movie = dir.path().join("m-%d.png");
    let out = ok(&[
        "render",
        s(&d),
        "-o",
        s(&movie),
        "--width",
        "32",
        "--height",
        "32",
        "--colour-map",
        "cool-warm",
    ]);
    assert!(
        out.contains(
            "vz from -16 to 16 (centred on 0, the map's white; every frame's range is -5 to 16"
        ),
        "{out}"
    );
    // A range that misses every frame's values: said.
    let out = ok(&[
        "render",
        s(&d),
        "-o",
        s(&movie),
        "--width",
        "16",
        "--height",
        "16",
        "--colour-map",
        "viridis",
        "--attribute-range",
        "100:200",
    ]);
    assert!(
        out.contains("misses every frame's values (vz from -5 to 16)"),
        "{out}"
    );
}

/// `--log-scale` maps decades evenly: a kinetic energy from 0 starts 4 decades below
/// its top, as the legend says; it needs a map (or attribute splats) and a positive
/// range.
#[test]
fn a_log_scale_colours_decades_and_says_where_it_starts() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("c.lammpstrj");
    generate(&["crater", "-n", "3000"], &dump);
    let file = dir.path().join("c.mdlod");
    ok(&["convert", s(&dump), "-o", s(&file), "--attribute", "c_ke"]);
    let png = dir.path().join("c.png");
    let render = |extra: &[&str]| {
        let mut args = vec![
            "render",
            s(&file),
            "-o",
            s(&png),
            "--width",
            "48",
            "--height",
            "36",
        ];
        args.extend(extra);
        (ok(&args), read_png(&png).2)
    };
    let (_, linear) = render(&["--colour-map", "viridis"]);
    let (out, log) = render(&["--colour-map", "viridis", "--log-scale"]);
    assert!(out.contains("on a log scale"), "{out}");
    assert_ne!(linear, log);
    let (out, _) = render(&[
        "--colour-map",
        "viridis",
        "--log-scale",
        "--attribute-range",
        "0.01:10",
    ]);
    assert!(
        out.contains("from 0.01 to 10 (--attribute-range), on a log scale\n"),
        "{out}"
    );
    let (_, linear_splats) = render(&["--mode", "splat", "--intensity", "attribute"]);
    let (out, splats) = render(&["--mode", "splat", "--intensity", "attribute", "--log-scale"]);
    assert!(
        out.contains("splat intensity") && out.contains("on a log scale"),
        "{out}"
    );
    assert!(splats.chunks(4).any(|p| p[..3] != [0, 0, 0]));
    assert_ne!(
        splats, linear_splats,
        "the log scale changes the splats' light"
    );
    let e = fails(&["render", s(&file), "-o", s(&png), "--log-scale"]);
    assert!(
        e.contains("--log-scale has no effect without --colour-map"),
        "{e}"
    );
    // A range from 0, as a movie's union of ranges may be: 4 decades below its top.
    let (out, _) = render(&[
        "--colour-map",
        "magma",
        "--log-scale",
        "--attribute-range",
        "0:10",
    ]);
    assert!(
        out.contains("on a log scale from 1.0000e-3 (4 decades below 10)"),
        "{out}"
    );
    // A movie's frames over a range from 0, in the summary too.
    let d = dir.path().join("c.d");
    ok(&["batch", s(&dump), "-o", s(&d), "--attribute", "c_ke"]);
    let movie = dir.path().join("m-%d.png");
    let out = ok(&[
        "render",
        s(&d),
        "-o",
        s(&movie),
        "--width",
        "24",
        "--height",
        "18",
        "--colour-map",
        "magma",
        "--log-scale",
        "--attribute-range",
        "0:1",
    ]);
    assert!(
        out.contains("on a log scale from 1.0000e-4 (4 decades below 1)"),
        "{out}"
    );

    // Frozen wall atoms at 0 among moving ones from 0.05: the scale starts at 0.05, not
    // four decades below the top, in one frame and in a movie.
    let frozen = dir.path().join("frozen.lammpstrj");
    let mut text = String::new();
    for step in [0, 100] {
        text.push_str(&format!(
            "ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ATOMS\n400\nITEM: BOX BOUNDS pp pp pp\n\
             0 40\n0 40\n0 2\nITEM: ATOMS id type x y z c_ke\n"
        ));
        for i in 0..400 {
            let (x, y) = ((i % 20) as f32 * 2.0, (i / 20) as f32 * 2.0);
            let ke = if i < 20 {
                0.0
            } else {
                0.05 + 0.55 * (i as f32 / 400.0)
            };
            text.push_str(&format!("{} 1 {x} {y} 1 {ke}\n", i + 1));
        }
    }
    std::fs::write(&frozen, text).unwrap();
    let file = dir.path().join("frozen.mdlod");
    ok(&["convert", s(&frozen), "-o", s(&file), "--attribute", "c_ke"]);
    let out = ok(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--width",
        "24",
        "--height",
        "18",
        "--colour-map",
        "magma",
        "--log-scale",
    ]);
    let legend = out
        .lines()
        .find(|l| l.contains("colour map magma"))
        .unwrap();
    assert!(
        legend.contains("c_ke from 0.07") && legend.contains("from the smallest value above 0"),
        "{out}"
    );
    let d = dir.path().join("frozen.d");
    ok(&["batch", s(&frozen), "-o", s(&d), "--attribute", "c_ke"]);
    let out = ok(&[
        "render",
        s(&d),
        "-o",
        s(&movie),
        "--width",
        "24",
        "--height",
        "18",
        "--colour-map",
        "magma",
        "--log-scale",
    ]);
    assert!(
        out.contains("c_ke from 0.07") && out.contains("every frame's range is 0 to"),
        "{out}"
    );
}

/// `--background none`: a PNG whose uncovered pixels are transparent, for figures laid
/// over anything; the modes that blend into a background refuse it.
#[test]
fn a_transparent_background_is_a_png_with_alpha() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("c.lammpstrj");
    generate(&["crater", "-n", "3000"], &dump);
    let file = dir.path().join("c.mdlod");
    ok(&["convert", s(&dump), "-o", s(&file)]);
    let png = dir.path().join("c.png");
    ok(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--width",
        "48",
        "--height",
        "36",
        "--background",
        "none",
        "--spp",
        "4",
    ]);
    let (_, _, px) = read_png(&png);
    let alphas: Vec<u8> = px.chunks(4).map(|p| p[3]).collect();
    assert_eq!(alphas[0], 0, "a corner is clear");
    assert!(alphas.contains(&255), "the crater is opaque");
    assert!(
        alphas.iter().any(|&a| a > 0 && a < 255),
        "edges are partly clear"
    );
    let e = fails(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--mode",
        "splat",
        "--background",
        "none",
    ]);
    assert!(
        e.contains("a transparent background is drawn in the spheres, splat-over, density"),
        "{e}"
    );
    // Nor white, where light added shows nothing; a colour map colours it over white.
    let white = ["--mode", "splat", "--background", "white"];
    let e = fails(&[&["render", s(&file), "-o", s(&png)][..], &white].concat());
    assert!(
        e.contains("--mode splat adds the splats' light to the background, and on white"),
        "{e}"
    );
    ok(&[
        &["render", s(&file), "-o", s(&png)][..],
        &white,
        &["--colour-map", "viridis"],
    ]
    .concat());
    let (_, _, px) = read_png(&png);
    assert!(
        px.chunks(4).any(|p| p[..3] != [255, 255, 255]),
        "splats show"
    );
    // The iso-surface and the volume: alpha their opacity.
    for mode in ["iso", "density", "splat-over"] {
        ok(&[
            "render",
            s(&file),
            "-o",
            s(&png),
            "--mode",
            mode,
            "--background",
            "none",
            "--width",
            "48",
            "--height",
            "36",
        ]);
        let (_, _, px) = read_png(&png);
        let alphas: Vec<u8> = px.chunks(4).map(|p| p[3]).collect();
        assert_eq!(alphas[0], 0, "{mode}: a corner is clear");
        assert!(
            alphas.iter().any(|&a| a > 128),
            "{mode}: the material shows"
        );
    }
}

/// The volume and its iso-surface are the same picture at any scale of the data: a
/// cloud in centimetres at galactic distances (5·10^19) as at 50 (a distance's square
/// overflowed single precision past 1.8·10^19, and the volume came out empty).
#[test]
fn the_volume_is_the_same_picture_at_any_scale() {
    let dir = tempfile::tempdir().unwrap();
    let pictures: Vec<Vec<u8>> = [1f64, 1e18]
        .iter()
        .map(|&scale| {
            let xyz = dir.path().join(format!("g{scale}.xyz"));
            let mut text = String::from("125\ngrid\n");
            for i in 0..125 {
                let (x, y, z) = (i % 5, i / 5 % 5, i / 25);
                let at = |k: i32| (40.0 + 2.5 * f64::from(k)) * scale;
                text += &format!("Cu {:e} {:e} {:e}\n", at(x), at(y), at(z));
            }
            std::fs::write(&xyz, text).unwrap();
            let file = xyz.with_extension("mdlod");
            let radius = format!("Cu={:e}", 0.8 * scale);
            ok(&["convert", s(&xyz), "-o", s(&file), "--radius", &radius]);
            let mut all = Vec::new();
            for mode in ["density", "iso"] {
                let png = dir.path().join(format!("{mode}{scale}.png"));
                ok(&[
                    "render",
                    s(&file),
                    "-o",
                    s(&png),
                    "--width",
                    "48",
                    "--height",
                    "36",
                    "--mode",
                    mode,
                    "--background",
                    "#000000",
                ]);
                all.extend(read_png(&png).2);
            }
            all
        })
        .collect();
    let lit = pictures[1]
        .chunks(4)
        .filter(|p| p[..3].iter().any(|&v| v > 40))
        .count();
    assert!(lit > 200, "{lit} pixels show the volume at 5·10^19");
    let off = pictures[0]
        .iter()
        .zip(&pictures[1])
        .filter(|(a, b)| a.abs_diff(**b) > 8)
        .count();
    assert!(off * 100 < pictures[0].len(), "{off} channels differ");
}

/// Splats lit by a value start its range at 0: a particle of the smallest mass still
/// shines, a third as bright as one of three times its mass (the file's range gave it no
/// light at all), in one image and in a movie.
#[test]
fn splats_lit_by_value_start_their_range_at_zero() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("masses.lammpstrj");
    let mut text = String::from(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n128\nITEM: BOX BOUNDS pp pp pp\n\
         0 16\n0 8\n0 2\nITEM: ATOMS id type x y z mass\n",
    );
    for i in 0..128 {
        let (x, y, z) = (i % 16, i / 16 % 8, i / 128);
        let mass = if x < 8 { 2.0 } else { 6.0 };
        text += &format!("{} 1 {}.5 {}.5 {}.5 {mass}\n", i + 1, x, y, z);
    }
    std::fs::write(&dump, text).unwrap();
    let file = dir.path().join("masses.mdlod");
    ok(&[
        "convert",
        s(&dump),
        "-o",
        s(&file),
        "--attribute",
        "mass",
        "--radius",
        "1=0.7",
    ]);
    let png = dir.path().join("m.png");
    let (w, h) = (128u32, 64u32);
    let out = ok(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--mode",
        "splat",
        "--intensity",
        "attribute",
        "--ortho",
        "--look-along",
        "0,0,-1",
        "--width",
        "128",
        "--height",
        "64",
        "--exposure",
        "0.02",
    ]);
    assert!(out.contains("mass from 0 to 6 (from 0, so that"), "{out}");
    let px = read_png(&png).2;
    // The mean grey of a column band of the picture.
    let band = |x0: u32, x1: u32| {
        let mut sum = 0u64;
        for y in h / 4..3 * h / 4 {
            for x in x0..x1 {
                sum += u64::from(px[4 * (y * w + x) as usize]);
            }
        }
        sum as f64 / f64::from((x1 - x0) * h / 2)
    };
    let (light, heavy) = (
        band(w / 4 - 10, w / 4 + 10),
        band(3 * w / 4 - 10, 3 * w / 4 + 10),
    );
    assert!(light > 10.0 && heavy > 1.5 * light, "{light} {heavy}");
    // Through a projection's colour map too (its log is the image's, not the splats').
    for extra in [&[][..], &["--log-scale"]] {
        let mut args = vec!["render", s(&file), "-o", s(&png), "--mode", "splat"];
        args.extend(["--intensity", "attribute", "--colour-map", "grey"]);
        args.extend(["--width", "32", "--height", "24"]);
        args.extend_from_slice(extra);
        let out = ok(&args);
        assert!(
            out.contains("mass from 0 to 6 (from 0, so that"),
            "{extra:?}: {out}"
        );
    }
    // A movie of the frame starts at 0 too.
    let d = dir.path().join("m.d");
    ok(&[
        "batch",
        s(&dump),
        "-o",
        s(&d),
        "--attribute",
        "mass",
        "--radius",
        "1=0.7",
    ]);
    let out = ok(&[
        "render",
        s(&d),
        "-o",
        s(&dir.path().join("f-%d.png")),
        "--mode",
        "splat",
        "--intensity",
        "attribute",
        "--width",
        "32",
        "--height",
        "24",
    ]);
    assert!(out.contains("mass from 0 to 6 (from 0, so that"), "{out}");
}

/// `--light-range` sets a projection's colour map ends, so that projections made apart
/// share one scale; options that have no effect on a projection say what does.
#[test]
fn a_projection_takes_its_light_range() {
    let dir = tempfile::tempdir().unwrap();
    let file = converted(dir.path(), "cu_melt.custom.dump");
    let (a, b) = (dir.path().join("a.png"), dir.path().join("b.png"));
    let base = |png: &Path, zoom: &str, range: &[&str]| {
        let mut args = vec!["render", s(&file), "-o", s(png), "--mode", "splat"];
        args.extend(["--colour-map", "magma", "--width", "48", "--height", "36"]);
        args.extend(["--zoom", zoom]);
        args.extend_from_slice(range);
        ok(&args)
    };
    let out = base(&b, "1", &["--light-range", "0:5"]);
    assert!(
        out.contains("from 0.0000e0 to 5.0000e0 (--light-range;"),
        "{out}"
    );
    let out = base(&b, "1", &["--light-range", "0:500"]);
    let dim = read_png(&b).2;
    base(&b, "1", &["--light-range", "0:5"]);
    let bright = read_png(&b).2;
    assert_ne!(dim, bright, "{out}");
    for (extra, says) in [
        (
            &["--exposure", "2"][..],
            "--light-range MIN:MAX sets its ends",
        ),
        (
            &["--attribute-range", "0:1"][..],
            "whose ends --light-range MIN:MAX sets",
        ),
        (
            &["--log-scale", "--light-range", "0:5"][..],
            "starts above 0",
        ),
    ] {
        let mut args = vec!["render", s(&file), "-o", s(&a), "--mode", "splat"];
        args.extend(["--colour-map", "magma"]);
        args.extend_from_slice(extra);
        let e = fails(&args);
        assert!(e.contains(says), "{extra:?}: {e}");
    }
    let e = fails(&["render", s(&file), "-o", s(&a), "--light-range", "0:5"]);
    assert!(e.contains("needs --mode splat and --colour-map"), "{e}");
    // White attribute light has no scale a legend could show (it used to get a key of
    // the species, which the picture does not show); with a map it has a bar.
    let svg = dir.path().join("l.svg");
    let pe = dir.path().join("pe.mdlod");
    let dump = lammps_sample_path("cu_melt.custom.dump");
    ok(&["convert", s(&dump), "-o", s(&pe), "--attribute", "c_pe"]);
    for legend in [&["--legend", s(&svg)][..], &["--legend-in-image"][..]] {
        let mut args = vec!["render", s(&pe), "-o", s(&a), "--mode", "splat"];
        args.extend([
            "--intensity",
            "attribute",
            "--width",
            "400",
            "--height",
            "240",
        ]);
        args.extend_from_slice(legend);
        let e = fails(&args);
        assert!(e.contains("add --colour-map (grey keeps it white)"), "{e}");
        assert!(!a.exists(), "refused before drawing");
        args.extend(["--colour-map", "grey"]);
        let out = ok(&args);
        // (Energies below 0: the light is the value less the smallest, in eV.)
        assert!(
            out.contains("the colour map over the projected (c_pe + 3.57615)"),
            "{out}"
        );
        std::fs::remove_file(&a).unwrap();
    }
}

/// Values far from 1 (a mass in grams, a density in g/cm³) print in scientific notation,
/// not as 34 digits.
#[test]
fn summaries_print_large_and_small_values_in_scientific_notation() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("cgs.lammpstrj");
    let mut text = String::from(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n8\nITEM: BOX BOUNDS pp pp pp\n\
         0 4\n0 4\n0 4\nITEM: ATOMS id type x y z mass\n",
    );
    for i in 0..8 {
        let mass = if i < 4 { "1.989e33" } else { "3.978e33" };
        text += &format!(
            "{} 1 {} {} {} {mass}\n",
            i + 1,
            i % 2 * 2,
            i / 2 % 2 * 2,
            i / 4 * 2
        );
    }
    std::fs::write(&dump, text).unwrap();
    let file = dir.path().join("cgs.mdlod");
    ok(&["convert", s(&dump), "-o", s(&file), "--attribute", "mass"]);
    let info = ok(&["info", s(&file)]);
    assert!(info.contains("mass in [1.989e33, 3.978e33]"), "{info}");
    let out = ok(&[
        "render",
        s(&file),
        "-o",
        s(&dir.path().join("m.png")),
        "--width",
        "32",
        "--height",
        "24",
        "--colour-map",
        "viridis",
    ]);
    assert!(out.contains("mass from 1.989e33 to 3.978e33"), "{out}");
    // A log scale over six decades stored linearly: the low decades are a few steps, and
    // the summary says how to keep them; over three decades, nothing to say.
    let original = std::fs::read_to_string(&dump).unwrap();
    for (small, says) in [("1e-6", true), ("1", false)] {
        let text = original
            .replace("1.989e33", small)
            .replace("3.978e33", "1000");
        std::fs::write(&dump, text).unwrap();
        ok(&["convert", s(&dump), "-o", s(&file), "--attribute", "mass"]);
        let out = ok(&[
            "render",
            s(&file),
            "-o",
            s(&dir.path().join("m.png")),
            "--width",
            "32",
            "--height",
            "24",
            "--colour-map",
            "viridis",
            "--log-scale",
        ]);
        assert_eq!(
            out.contains("convert with --attribute-log10=mass to keep them"),
            says,
            "{out}"
        );
        // Steps of 0.0153 from 1e-6: the 4 decades below the step hold no value of
        // their own (they all read as the start, the map's first colour).
        assert_eq!(
            out.contains("so 4 of the scale's 9 decades show no step of their own"),
            says,
            "{out}"
        );
    }
}

/// Splats of species light take `--species-colour`, particles and clusters alike, and
/// keep their flux (the file's radii); splats lit by the attribute refuse it.
#[test]
fn splats_take_species_colours() {
    let dir = tempfile::tempdir().unwrap();
    let file = converted(dir.path(), "cu_melt.custom.dump");
    let png = dir.path().join("s.png");
    // The summed red and green of the picture.
    let colours = |extra: &[&str]| {
        let mut args = vec!["render", s(&file), "-o", s(&png), "--width", "48"];
        args.extend(["--height", "36"]);
        args.extend_from_slice(extra);
        ok(&args);
        read_png(&png).2.chunks(4).fold([0u64; 3], |mut sum, p| {
            for k in 0..3 {
                sum[k] += u64::from(p[k]);
            }
            sum
        })
    };
    for mode in ["splat", "splat-over"] {
        for error in ["0", "16"] {
            let base = ["--mode", mode, "--screen-error", error];
            let plain = colours(&base);
            let green = colours(&[&base[..], &["--species-colour", "1=#00ff00"]].concat());
            assert!(
                green[1] > green[0] * 2 && plain[0] > plain[1],
                "{mode} at {error} px: {plain:?} against {green:?}"
            );
        }
    }
    let mut args = vec!["render", s(&file), "-o", s(&png), "--mode", "splat"];
    args.extend(["--species-colour", "1=#00ff00", "--intensity", "attribute"]);
    let e = fails(&args);
    assert!(e.contains("--species-colour"), "{e}");
}

/// A volume whose one clip plane cuts away every sample says so (its particles are drawn
/// into nothing), and keeps quiet where the plane cuts through it.
#[test]
fn a_volume_clipped_to_nothing_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("a.mdlod");
    ok(&[
        "convert",
        s(&lammps_sample_path("cuag_alloy.unwrapped.dump")),
        "-o",
        s(&file),
    ]);
    let png = dir.path().join("v.png");
    for (plane, says) in [("1,0,0,-100", true), ("1,0,0,10", false)] {
        for mode in ["density", "iso"] {
            let clip = format!("--clip={plane}");
            let out = ok(&[
                "render",
                s(&file),
                "-o",
                s(&png),
                "--width",
                "32",
                "--height",
                "24",
                "--mode",
                mode,
                &clip,
            ]);
            assert_eq!(
                out.contains("cuts away every sample of the volume"),
                says,
                "{mode} {plane}: {out}"
            );
        }
    }
}

/// A ball of atoms fills the image as a ball does: the fit frames its clusters, not its
/// box's empty corners (which left it at about two thirds of the height).
#[test]
fn a_ball_of_atoms_fills_the_image() {
    let dir = tempfile::tempdir().unwrap();
    let file = argon_ball(dir.path(), 12);
    let xyz = dir.path().join("ball.xyz");
    let png = dir.path().join("ball.png");
    let (w, h) = (96u32, 72u32);
    for extra in [
        &[][..],
        &["--ortho"],
        &["--elevation", "60", "--azimuth", "200"],
    ] {
        let mut args = vec!["render", s(&file), "-o", s(&png), "--width", "96"];
        args.extend(["--height", "72", "--background", "#000000"]);
        args.extend_from_slice(extra);
        ok(&args);
        let px = read_png(&png).2;
        let lit =
            |y: u32| (0..w).any(|x| px[4 * (y * w + x) as usize..][..3].iter().any(|&v| v > 8));
        let rows: Vec<u32> = (0..h).filter(|&y| lit(y)).collect();
        let (top, bottom) = (rows[0], rows[rows.len() - 1]);
        assert!(
            top >= 1 && bottom < h - 1,
            "{extra:?}: rows {top} to {bottom}"
        );
        assert!(
            bottom - top + 1 >= h * 4 / 5,
            "{extra:?}: rows {top} to {bottom} of {h}"
        );
        // Centred: as many empty rows above as below, within a few.
        assert!(
            (top as i32 - (h - 1 - bottom) as i32).abs() <= 3,
            "{extra:?}: {top} {bottom}"
        );
    }
    // A movie frames its frames' clusters the same way.
    let d = dir.path().join("ball.d");
    ok(&["batch", s(&xyz), "-o", s(&d), "--radius", "Ar=0.5"]);
    let frames = dir.path().join("f-%d.png");
    let mut args = vec!["render", s(&d), "-o", s(&frames), "--width", "96"];
    args.extend(["--height", "72", "--background", "#000000"]);
    ok(&args);
    let px = read_png(&dir.path().join("f-0.png")).2;
    let lit = |y: u32| (0..w).any(|x| px[4 * (y * w + x) as usize..][..3].iter().any(|&v| v > 8));
    let rows: Vec<u32> = (0..h).filter(|&y| lit(y)).collect();
    assert!(
        rows.len() as u32 >= h * 4 / 5 && rows[0] >= 1,
        "movie: rows {rows:?}"
    );
}

/// A small ball of atoms (a nanoparticle of a few hundred, with no level of clusters
/// between its atoms and the top node) fills and centres the image as a large one: the
/// fit frames its atoms' spheres, not its box (which left it at two thirds of the height,
/// and a perspective view off-centre).
#[test]
fn a_small_ball_of_atoms_fills_and_centres_the_image() {
    let dir = tempfile::tempdir().unwrap();
    let file = argon_ball(dir.path(), 4);
    let png = dir.path().join("ball.png");
    for extra in [
        &[][..],
        &["--ortho"],
        &["--elevation", "60", "--azimuth", "200"],
    ] {
        let mut args = vec!["render", s(&file), "-o", s(&png), "--width", "96"];
        args.extend(["--height", "72", "--background", "#000000"]);
        args.extend_from_slice(extra);
        ok(&args);
        let ([top, bottom], [left, right]) = lit_extent(&png);
        let (w, h) = (96u32, 72u32);
        assert!(
            bottom - top + 1 >= h * 4 / 5,
            "{extra:?}: rows {top} to {bottom} of {h}"
        );
        assert!(
            (top as i32 - (h - 1 - bottom) as i32).abs() <= 3
                && (left as i32 - (w - 1 - right) as i32).abs() <= 3,
            "{extra:?}: rows {top} to {bottom}, columns {left} to {right}"
        );
    }
}

/// A ball of argon atoms on a unit lattice within `radius`, converted with radius 0.5.
fn argon_ball(dir: &Path, radius: i32) -> PathBuf {
    let xyz = dir.join("ball.xyz");
    let mut atoms = Vec::new();
    for i in -radius..=radius {
        for j in -radius..=radius {
            for k in -radius..=radius {
                if i * i + j * j + k * k <= radius * radius {
                    atoms.push(format!("Ar {} {} {}", i, j, k));
                }
            }
        }
    }
    std::fs::write(
        &xyz,
        format!("{}\nball\n{}\n", atoms.len(), atoms.join("\n")),
    )
    .unwrap();
    let file = dir.join("ball.mdlod");
    ok(&["convert", s(&xyz), "-o", s(&file), "--radius", "Ar=0.5"]);
    file
}

/// The first and last rows, and columns, of a PNG holding a pixel brighter than black.
fn lit_extent(png: &Path) -> ([u32; 2], [u32; 2]) {
    let (w, h, px) = read_png(png);
    let on = |x: u32, y: u32| px[4 * (y * w + x) as usize..][..3].iter().any(|&v| v > 8);
    let rows: Vec<u32> = (0..h).filter(|&y| (0..w).any(|x| on(x, y))).collect();
    let cols: Vec<u32> = (0..w).filter(|&x| (0..h).any(|y| on(x, y))).collect();
    (
        [rows[0], rows[rows.len() - 1]],
        [cols[0], cols[cols.len() - 1]],
    )
}

/// A slanted cell drawn with `--cell` is framed by its corners, not by its bounding box
/// (whose corners lie outside it: an fcc primitive cell filled 64 % of the height).
#[test]
fn a_slanted_cell_is_framed_by_its_corners() {
    let dir = tempfile::tempdir().unwrap();
    let xyz = dir.path().join("prim.xyz");
    let (a, b, c) = ([0.0, 7.2, 7.2], [7.2, 0.0, 7.2], [7.2, 7.2, 0.0]);
    let mut atoms = Vec::new();
    for i in 0..4 {
        for j in 0..4 {
            for k in 0..4 {
                let f = [i, j, k].map(|n| n as f64 / 4.0);
                let p: Vec<String> = (0..3)
                    .map(|x| (f[0] * a[x] + f[1] * b[x] + f[2] * c[x]).to_string())
                    .collect();
                atoms.push(format!("Cu {}", p.join(" ")));
            }
        }
    }
    std::fs::write(
        &xyz,
        format!(
            "{}\nLattice=\"0 7.2 7.2 7.2 0 7.2 7.2 7.2 0\" Properties=species:S:1:pos:R:3\n{}\n",
            atoms.len(),
            atoms.join("\n")
        ),
    )
    .unwrap();
    let file = dir.path().join("prim.mdlod");
    ok(&["convert", s(&xyz), "-o", s(&file)]);
    let png = dir.path().join("prim.png");
    let h = 90u32;
    for extra in [&[][..], &["--ortho"]] {
        let mut args = vec!["render", s(&file), "-o", s(&png), "--width", "160"];
        args.extend(["--height", "90", "--background", "#000000", "--cell"]);
        args.extend_from_slice(extra);
        ok(&args);
        let ([top, bottom], _) = lit_extent(&png);
        assert!(
            bottom - top + 1 >= h * 4 / 5,
            "{extra:?}: rows {top} to {bottom} of {h}"
        );
    }
}

/// A fitted view frames the particles as they are drawn: spheres enlarged by the style,
/// a splat's Gaussian, a density kernel's support; never cropped, never tiny.
#[test]
fn a_fitted_view_frames_the_particles_as_drawn() {
    let dir = tempfile::tempdir().unwrap();
    let xyz = dir.path().join("one.xyz");
    std::fs::write(&xyz, "1\none atom\nCu 3.72 5.72 -4.28\n").unwrap();
    let file = dir.path().join("one.mdlod");
    ok(&["convert", s(&xyz), "-o", s(&file)]);
    let png = dir.path().join("one.png");
    let (w, h) = (80u32, 60u32);
    // The first and last rows with a pixel brighter than 8 in any channel.
    let rows = |extra: &[&str]| {
        let mut args = vec!["render", s(&file), "-o", s(&png), "--width", "80"];
        args.extend(["--height", "60", "--background", "#000000"]);
        args.extend_from_slice(extra);
        ok(&args);
        let px = read_png(&png).2;
        let lit =
            |y: u32| (0..w).any(|x| px[4 * (y * w + x) as usize..][..3].iter().any(|&v| v > 8));
        let on: Vec<u32> = (0..h).filter(|&y| lit(y)).collect();
        (on[0], on[on.len() - 1])
    };
    for extra in [
        &[][..],
        &["--radius-scale", "3"],
        &["--radius-scale", "0.3"],
        &["--species-radius", "Cu=8"],
        &["--mode", "splat"],
        &["--mode", "splat-over"],
        &["--mode", "density"],
    ] {
        let (top, bottom) = rows(extra);
        assert!(
            top >= 1 && bottom < h - 1,
            "{extra:?}: rows {top} to {bottom} of {h}"
        );
        assert!(
            bottom - top > h * 2 / 5,
            "{extra:?}: rows {top} to {bottom} of {h}"
        );
    }
}

/// `--turntable N`: N views a full turn apart about z, all looking at the data's centre
/// from one distance: the largest of the views' fitted distances (a fit depends on the
/// direction), so no view crops the data; each the image a single render of the first
/// view, saved, turned to that azimuth gives; one file only.
#[test]
fn a_turntable_renders_a_full_turn_of_views() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("a.lammpstrj");
    generate(&["alloy", "-n", "3000"], &dump);
    let file = dir.path().join("a.mdlod");
    ok(&["convert", s(&dump), "-o", s(&file)]);
    let pattern = dir.path().join("spin").join("v-%02d.png");
    let saved = dir.path().join("first.json");
    let size = ["--width", "40", "--height", "30", "--elevation", "15"];
    let mut args = vec![
        "render",
        s(&file),
        "-o",
        s(&pattern),
        "--turntable",
        "3",
        "--azimuth",
        "10",
        "--save-view",
        s(&saved),
    ];
    args.extend(size);
    let out = ok(&args);
    assert!(
        out.contains("rendered 3 views")
            && out.contains("from azimuth 10°")
            && out.contains("azimuth 250.0°"),
        "{out}"
    );
    let distance = |view: &Path| {
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(view).unwrap()).unwrap();
        v["distance"].as_f64().unwrap()
    };
    let single = dir.path().join("single.png");
    let fitted = dir.path().join("fitted.json");
    let (mut farthest, mut nearest) = (0.0f64, f64::MAX);
    for azimuth in ["10", "130", "250"] {
        let mut args = vec!["render", s(&file), "-o", s(&single), "--azimuth", azimuth];
        args.extend(["--save-view", s(&fitted)]);
        args.extend(size);
        ok(&args);
        farthest = farthest.max(distance(&fitted));
        nearest = nearest.min(distance(&fitted));
    }
    // The square slab is fitted closer seen along an axis than across its diagonal. A
    // still's fit centres the picture by moving its target, which brings it closer than
    // a view of the data's centre: the turn is at least as far as each.
    assert!(farthest > nearest * 1.01, "{farthest} {nearest}");
    assert!(
        distance(&saved) >= farthest,
        "{} {farthest}",
        distance(&saved)
    );
    assert!(
        distance(&saved) < farthest * 1.2,
        "{} {farthest}",
        distance(&saved)
    );
    let info: serde_json::Value = serde_json::from_str(&ok(&["info", s(&file), "--json"])).unwrap();
    let view: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&saved).unwrap()).unwrap();
    for k in 0..3 {
        let centre = 0.5
            * (info["extent"]["min"][k].as_f64().unwrap()
                + info["extent"]["max"][k].as_f64().unwrap());
        let target = view["target"][k].as_f64().unwrap();
        assert!(
            (target - centre).abs() < 1e-3 * (1.0 + centre.abs()),
            "{k}: {target} {centre}"
        );
    }
    for (view, azimuth) in [(0, "10"), (1, "130")] {
        let mut args = vec!["render", s(&file), "-o", s(&single), "--view", s(&saved)];
        args.extend(["--azimuth", azimuth, "--width", "40", "--height", "30"]);
        ok(&args);
        let spun = dir.path().join("spin").join(format!("v-{view:02}.png"));
        assert_eq!(
            read_png(&spun),
            read_png(&single),
            "view {view} at {azimuth}°"
        );
    }
    assert_ne!(
        read_png(&dir.path().join("spin/v-01.png")),
        read_png(&dir.path().join("spin/v-02.png"))
    );
    let e = fails(&["render", s(&file), "-o", s(&single), "--turntable", "4"]);
    assert!(
        e.contains("--turntable renders one image per view") && e.contains("%d"),
        "{e}"
    );
    let d = dir.path().join("a.d");
    ok(&["batch", s(&dump), "-o", s(&d)]);
    let e = fails(&["render", s(&d), "-o", s(&pattern), "--turntable", "4"]);
    // (Its first frame file named, as the batch wrote it.)
    let first = mdlod_preprocess::batch::read_manifest(&d).unwrap().frames[0]
        .file
        .clone();
    assert!(
        e.contains("--turntable spins one file")
            && e.contains(&format!("e.g. {}", s(&d.join(first)))),
        "{e}"
    );
}

/// A text dump whose last line has no line end converts (a hand-written file may lack
/// it) with a note: a run still writing it may have stopped inside a number.
#[test]
fn a_last_line_without_a_line_end_is_noted() {
    let dir = tempfile::tempdir().unwrap();
    let xyz = dir.path().join("nl.xyz");
    std::fs::write(&xyz, "2\nplain\nCu 0 0 0\nCu 2.5 0 0.41").unwrap();
    let out = ok(&["convert", s(&xyz), "-o", s(&dir.path().join("nl.mdlod"))]);
    assert!(out.contains("its last line has no line end"), "{out}");
    std::fs::write(&xyz, "2\nplain\nCu 0 0 0\nCu 2.5 0 0.41\n").unwrap();
    let out = ok(&["convert", s(&xyz), "-o", s(&dir.path().join("nl2.mdlod"))]);
    assert!(!out.contains("line end"), "{out}");
}

/// `--hide-species` in the splat and volume modes: the light or density of the species
/// shown only, as a file of those species alone gives (at screen error 0, the same
/// particles).
#[test]
fn hidden_species_leave_the_splats_and_the_volume() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("a.lammpstrj");
    generate(&["alloy", "-n", "3000"], &dump);
    // The same dump with its silver (type 2) atoms only.
    let text = std::fs::read_to_string(&dump).unwrap();
    let (head, atoms) = text.split_once("ITEM: ATOMS").unwrap();
    let (columns, lines) = atoms.split_once('\n').unwrap();
    let silver: Vec<&str> = lines
        .lines()
        .filter(|l| l.split_whitespace().nth(1) == Some("2"))
        .collect();
    assert!(silver.len() > 100, "{} silver atoms", silver.len());
    let count = text.lines().nth(3).unwrap();
    let head = head.replacen(&format!("\n{count}\n"), &format!("\n{}\n", silver.len()), 1);
    let only = dir.path().join("silver.lammpstrj");
    std::fs::write(
        &only,
        format!("{head}ITEM: ATOMS{columns}\n{}\n", silver.join("\n")),
    )
    .unwrap();
    let (all, ag) = (dir.path().join("a.mdlod"), dir.path().join("ag.mdlod"));
    ok(&[
        "convert",
        s(&dump),
        "-o",
        s(&all),
        "--radius",
        "1=1.28",
        "--radius",
        "2=1.44",
    ]);
    ok(&["convert", s(&only), "-o", s(&ag), "--radius", "2=1.44"]);
    for mode in ["iso", "density", "splat"] {
        let render = |file: &Path, name: &str, extra: &[&str]| {
            let png = dir.path().join(format!("{mode}-{name}.png"));
            let mut args = vec!["render", s(file), "-o", s(&png), "--mode", mode];
            args.extend(["--width", "48", "--height", "36", "--screen-error", "0"]);
            args.extend(extra);
            let out = ok(&args);
            (out, read_png(&png).2)
        };
        let (out, hidden) = render(&all, "hidden", &["--hide-species", "1"]);
        assert!(
            out.contains("of hidden species left out of the clusters opened"),
            "{mode}: {out}"
        );
        // The volume's legend: the spheres' packing, not an attribute.
        let legend = match mode {
            "iso" => "iso-surface where the particles' spheres fill a volume fraction of 0.3",
            "density" => "colours: the volume fraction the particles' spheres fill",
            _ => "splats: total flux",
        };
        assert!(out.contains(legend), "{mode}: {out}");
        let (_, alone) = render(&ag, "alone", &[]);
        let (_, everything) = render(&all, "all", &[]);
        let diff = |a: &[u8], b: &[u8]| {
            a.iter()
                .zip(b)
                .map(|(x, y)| f64::from(x.abs_diff(*y)))
                .sum::<f64>()
                / a.len() as f64
        };
        assert!(
            diff(&hidden, &alone) < 2.0,
            "{mode}: {}",
            diff(&hidden, &alone)
        );
        assert!(
            diff(&hidden, &everything) > 4.0 * diff(&hidden, &alone).max(0.5),
            "{mode}"
        );
    }
}

/// `--mode iso --colour-map`: the surface takes the map's colour of the attribute's
/// kernel-weighted mean, the legend is the map's colour bar, and `--log-scale` is the
/// attribute's; the volume (`--mode density --colour-map`) takes the map's colours with
/// the density's opacity.
#[test]
fn iso_surfaces_and_volumes_are_coloured_by_the_attribute_through_a_map() {
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| dir.path().join(n);
    let file = d("a.mdlod");
    let input = lammps_sample_path("cu_melt.custom.dump");
    ok(&[
        "convert",
        s(&input),
        "-o",
        s(&file),
        "--last",
        "--attribute",
        "c_pe",
    ]);
    let (png, svg, plain) = (d("m.png"), d("m.svg"), d("p.png"));
    let base = [
        "render",
        s(&file),
        "--mode",
        "iso",
        "--width",
        "64",
        "--height",
        "48",
    ];
    let out = ok(&[
        &base[..],
        &["-o", s(&png), "--colour-map", "magma", "--legend", s(&svg)],
    ]
    .concat());
    assert!(out.contains("colour map magma: c_pe from"), "{out}");
    assert!(
        out.contains("coloured by the mean of the attribute around it"),
        "{out}"
    );
    let key = std::fs::read_to_string(&svg).unwrap();
    assert!(key.contains(">c_pe</text>"), "{key}");
    ok(&[&base[..], &["-o", s(&plain)]].concat());
    // The surface in a species colour given (it was refused, though the surface takes
    // its species' colours): copper's reddish surface turns blue.
    let info: serde_json::Value = serde_json::from_str(&ok(&["info", "--json", s(&file)])).unwrap();
    let name = info["species"][0]["name"].as_str().unwrap().to_string();
    let (blue, key) = (d("b.png"), d("b.svg"));
    ok(&[
        &base[..],
        &[
            "-o",
            s(&blue),
            "--species-colour",
            &format!("{name}=#3050ff"),
            "--legend",
            s(&key),
        ],
    ]
    .concat());
    // Its key says the colour drawn, not the file's.
    let key = std::fs::read_to_string(&key).unwrap();
    assert!(key.to_lowercase().contains("#3050ff"), "{key}");
    let mean = |px: &[u8]| {
        let covered: Vec<&[u8]> = px
            .chunks_exact(4)
            .filter(|p| p[3] == 255 && p[..3] != [255, 255, 255])
            .collect();
        assert!(!covered.is_empty());
        [0, 1, 2]
            .map(|k| covered.iter().map(|p| f64::from(p[k])).sum::<f64>() / covered.len() as f64)
    };
    let (own, given) = (mean(&read_png(&plain).2), mean(&read_png(&blue).2));
    assert!(
        own[0] > own[2] && given[2] > 2.0 * given[0],
        "{own:?} {given:?}"
    );
    let e = fails(
        &[
            &base[..],
            &[
                "-o",
                s(&blue),
                "--colour-map",
                "magma",
                "--species-colour",
                &format!("{name}=red"),
            ],
        ]
        .concat(),
    );
    assert!(e.contains("--species-colour") && e.contains("iso"), "{e}");
    let (mapped, species) = (read_png(&png).2, read_png(&plain).2);
    // Copper's one colour against the map's many: more distinct hues on the surface.
    let hues = |px: &[u8]| {
        px.chunks_exact(4)
            .filter(|p| p[3] == 255 && p[..3] != [255, 255, 255])
            .map(|p| {
                let m = f32::from(p[0].max(p[1]).max(p[2]).max(1));
                [p[0], p[1], p[2]].map(|c| (f32::from(c) / m * 8.0).round() as u8)
            })
            .collect::<std::collections::BTreeSet<_>>()
            .len()
    };
    assert!(
        hues(&mapped) > 3 * hues(&species),
        "{} against {}",
        hues(&mapped),
        hues(&species)
    );
    // The volume coloured by it: the map's colours, the density's opacity.
    let volume = d("v.png");
    let out = ok(&[
        &[
            "render",
            s(&file),
            "--mode",
            "density",
            "--width",
            "64",
            "--height",
            "48",
        ][..],
        &[
            "-o",
            s(&volume),
            "--colour-map",
            "magma",
            "--legend",
            s(&svg),
        ],
    ]
    .concat());
    assert!(
        out.contains("colour map magma: c_pe from")
            && out.contains("colours: the attribute's mean at each sample"),
        "{out}"
    );
    assert!(std::fs::read_to_string(&svg)
        .unwrap()
        .contains(">c_pe</text>"));
    assert!(hues(&read_png(&volume).2) > 3, "{out}");
    // A file that keeps no attribute: said so, with how to keep one, in either mode.
    let bare = d("bare.mdlod");
    ok(&["convert", s(&input), "-o", s(&bare), "--last"]);
    for mode in ["density", "iso"] {
        let err = fails(&[
            "render",
            s(&bare),
            "-o",
            s(&png),
            "--mode",
            mode,
            "--colour-map",
            "magma",
        ]);
        assert!(
            err.contains("has no per-particle attribute to colour by")
                && err.contains("--attribute COLUMN"),
            "{mode}: {err}"
        );
    }
    // A range of one's own, as for spheres: the same scale in every panel or frame.
    let out = ok(&[
        &base[..],
        &[
            "-o",
            s(&png),
            "--colour-map",
            "magma",
            "--attribute-range=-4:-2",
        ],
    ]
    .concat());
    assert!(
        out.contains("colour map magma: c_pe from -4 to -2 (--attribute-range)"),
        "{out}"
    );
    // The attribute's log scale, not the volume fraction's (c_pe, all below 0, has no
    // log scale to show).
    let log = ok(&[
        &base[..],
        &["-o", s(&png), "--colour-map", "magma", "--log-scale"],
    ]
    .concat());
    assert!(
        log.contains("--log-scale left unused: no value of the range is above 0"),
        "{log}"
    );
}

/// `--mode splat --colour-map`: the image's light (projected flux or attribute) through
/// the map, with `--log-scale` on a log axis, and the legend says over which range; a
/// movie keeps the first frame's range.
#[test]
fn splats_colour_their_projection_through_a_map() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("c.lammpstrj");
    generate(&["crater", "-n", "3000", "--frames", "2"], &dump);
    let file = dir.path().join("c.mdlod");
    ok(&["convert", s(&dump), "-o", s(&file), "--attribute", "c_ke"]);
    let png = dir.path().join("p.png");
    let render = |extra: &[&str]| {
        let mut args = vec!["render", s(&file), "-o", s(&png), "--mode", "splat"];
        args.extend(["--width", "48", "--height", "36"]);
        args.extend(extra);
        (ok(&args), read_png(&png).2)
    };
    let (_, toned) = render(&[]);
    let (out, mapped) = render(&["--colour-map", "magma", "--log-scale"]);
    assert!(
        out.contains("colour map magma: the image's light (the projected flux) from")
            && out.contains("on a log scale (its lit pixels' 0.5th to 99.5th percentile"),
        "{out}"
    );
    assert_ne!(toned, mapped);
    let (out, linear) = render(&["--colour-map", "magma"]);
    assert!(
        out.contains("(0 to its lit pixels' 99.5th percentile"),
        "{out}"
    );
    assert_ne!(linear, mapped);
    let (out, _) = render(&["--colour-map", "viridis", "--intensity", "attribute"]);
    assert!(
        out.contains("splat intensity: c_ke from")
            && out.contains("the image's light (the projected c_ke) from 0.0000e0"),
        "{out}"
    );
    let d = dir.path().join("c.d");
    ok(&["batch", s(&dump), "-o", s(&d)]);
    let movie = dir.path().join("m-%d.png");
    ok(&[
        "render",
        s(&d),
        "-o",
        s(&movie),
        "--mode",
        "splat",
        "--colour-map",
        "magma",
        "--log-scale",
        "--width",
        "24",
        "--height",
        "18",
    ]);
}

/// Per-particle sizes in a text or binary dump (a granular run's `radius` or `diameter`
/// column, an extended XYZ radius property) are each particle's radius: the file keeps
/// them, whole or in chunks alike, `info` shows them, every mode renders them, and
/// `--radius` gives a type one radius again.
#[test]
fn a_granular_runs_grain_sizes_are_kept_per_particle() {
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| dir.path().join(n);
    let info = |f: &Path| -> serde_json::Value {
        serde_json::from_str(&ok(&["info", s(f), "--json"])).unwrap()
    };
    let text = lammps_sample_path("granular.dump");
    let out = ok(&["convert", s(&text), "-o", s(&d("g.mdlod")), "--last"]);
    assert!(!out.contains("note:"), "{out}");
    let v = info(&d("g.mdlod"));
    assert_eq!(v["format_version"], "1.1");
    let (lo, hi) = (
        v["radius"]["min"].as_f64().unwrap(),
        v["radius"]["max"].as_f64().unwrap(),
    );
    assert!(
        (0.3..0.35).contains(&lo) && (0.85..0.9).contains(&hi),
        "{v}"
    );
    let text_info = ok(&["info", s(&d("g.mdlod"))]);
    assert!(
        text_info.contains("each drawn at its own")
            && text_info.contains("radii        each particle's own"),
        "{text_info}"
    );
    // The same frame built in chunks, and from the binary dump's diameters: the same
    // grains (the binary's full precision within the text's six digits).
    ok(&[
        "convert",
        s(&text),
        "-o",
        s(&d("gc.mdlod")),
        "--last",
        "--chunk-points",
        "64",
        "--root-points",
        "16",
    ]);
    let bin = lammps_sample_path("granular.bin");
    ok(&["convert", s(&bin), "-o", s(&d("gb.mdlod")), "--last"]);
    let radii = |f: &Path| {
        let f = MdlodFile::open(f).unwrap();
        f.verify().unwrap();
        let mut r: Vec<f32> = (0..f.particle_count() as usize)
            .map(|i| f.particle_radius(i))
            .collect();
        r.sort_by(f32::total_cmp);
        r
    };
    let (whole, chunked, binary) = (
        radii(&d("g.mdlod")),
        radii(&d("gc.mdlod")),
        radii(&d("gb.mdlod")),
    );
    assert_eq!(whole, chunked);
    assert_eq!(whole.len(), 252);
    for (a, b) in whole.iter().zip(&binary) {
        assert!((a - b).abs() < 2e-5, "{a} against {b}");
    }
    for mode in ["spheres", "sndf", "splat", "density"] {
        ok(&[
            "render",
            s(&d("gc.mdlod")),
            "-o",
            s(&d(&format!("{mode}.png"))),
            "--mode",
            mode,
            "--width",
            "48",
            "--height",
            "36",
        ]);
    }
    // Two types given one name: their grains' mean radius, whole and in chunks.
    for chunks in [
        &[][..],
        &["--chunk-points", "64", "--root-points", "16"][..],
    ] {
        let out = d("merged.mdlod");
        let mut args = vec!["convert", s(&text), "-o", s(&out), "--last"];
        args.extend_from_slice(&["--species-name", "1=A", "--species-name", "2=A"]);
        args.extend_from_slice(chunks);
        ok(&args);
        let mean = whole.iter().map(|&r| f64::from(r)).sum::<f64>() / whole.len() as f64;
        let v = info(&out);
        let r = v["species"][0]["radius"].as_f64().unwrap();
        assert!((r - mean).abs() < 1e-4, "{r} against {mean}");
    }
    // An override gives the type one radius; the other keeps its grains' own.
    ok(&[
        "convert",
        s(&text),
        "-o",
        s(&d("o.mdlod")),
        "--last",
        "--radius",
        "2=0.75",
    ]);
    let v = info(&d("o.mdlod"));
    assert_eq!(v["species"][1]["radius"], 0.75);
    // (Its grains are stored at that radius, the range's end.)
    assert_eq!(v["radius"]["max"], 0.75, "{v}");
    assert!(v["radius"]["min"].as_f64().unwrap() < 0.35, "{v}");
    ok(&[
        "convert",
        s(&text),
        "-o",
        s(&d("m.mdlod")),
        "--last",
        "--radius",
        "1=0.4",
        "--radius",
        "2=0.75",
    ]);
    let v = info(&d("m.mdlod"));
    assert!(v["radius"].is_null() && v["format_version"] == "1.0", "{v}");

    // An extended XYZ radius property, also as the attribute.
    let xyz = d("r.xyz");
    std::fs::write(
        &xyz,
        "2\nProperties=species:S:1:pos:R:3:radius:R:1\nCu 0 0 0 1.2\nCu 2.5 0 0 1.4\n",
    )
    .unwrap();
    for extra in [&[][..], &["--attribute", "radius"][..]] {
        let out = d("r.mdlod");
        let mut args = vec!["convert", s(&xyz), "-o", s(&out)];
        args.extend_from_slice(extra);
        ok(&args);
        let mut r = radii(&d("r.mdlod"));
        r.dedup();
        assert!(
            (r[0] - 1.2).abs() < 1e-6 && (r[1] - 1.4).abs() < 1e-6,
            "{r:?}"
        );
    }
}

/// The size column can be named (an SPH run's smoothing length `h` as the radius, a
/// `d` as the diameter) or left out (`--no-sizes`); a batch converts its frames again
/// when the choice changes; inputs whose sizes come from no column refuse a named one.
#[test]
fn size_columns_can_be_named_or_left_out() {
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| dir.path().join(n);
    let info = |f: &Path| -> serde_json::Value {
        serde_json::from_str(&ok(&["info", s(f), "--json"])).unwrap()
    };
    let mut text = String::from(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n4\nITEM: BOX BOUNDS pp pp pp\n0 40\n0 4\n0 4\n\
         ITEM: ATOMS id type x y z h d\n",
    );
    for i in 0..4 {
        text.push_str(&format!(
            "{} 1 {} 2 2 {} {}\n",
            i + 1,
            10 * i,
            0.5 + i as f32,
            3 * (i + 1)
        ));
    }
    std::fs::write(d("sph.dump"), &text).unwrap();
    let radii = |f: &Path| {
        let f = MdlodFile::open(f).unwrap();
        let mut r: Vec<f32> = (0..4).map(|i| f.particle_radius(i)).collect();
        r.sort_by(f32::total_cmp);
        r
    };
    ok(&[
        "convert",
        s(&d("sph.dump")),
        "-o",
        s(&d("h.mdlod")),
        "--radius-column",
        "h",
    ]);
    let close = |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-4);
    assert!(
        close(&radii(&d("h.mdlod")), &[0.5, 1.5, 2.5, 3.5]),
        "{:?}",
        radii(&d("h.mdlod"))
    );
    ok(&[
        "convert",
        s(&d("sph.dump")),
        "-o",
        s(&d("d.mdlod")),
        "--diameter-column",
        "d",
    ]);
    assert!(
        close(&radii(&d("d.mdlod")), &[1.5, 3.0, 4.5, 6.0]),
        "{:?}",
        radii(&d("d.mdlod"))
    );
    // Without the option, neither `h` nor `d` is a size column.
    ok(&["convert", s(&d("sph.dump")), "-o", s(&d("plain.mdlod"))]);
    assert!(info(&d("plain.mdlod"))["radius"].is_null());
    let e = fails(&[
        "convert",
        s(&d("sph.dump")),
        "-o",
        s(&d("x.mdlod")),
        "--radius-column",
        "rho",
    ]);
    assert!(
        e.contains(
            "sph.dump:9: no column `rho` for --radius-column; the columns are id type x y z h d"
        ),
        "{e}"
    );
    // `--no-sizes`: a granular dump's radius column is not read.
    let gran = lammps_sample_path("granular.dump");
    ok(&["convert", s(&gran), "-o", s(&d("n.mdlod")), "--no-sizes"]);
    let v = info(&d("n.mdlod"));
    assert!(
        v["radius"].is_null() && v["species"][0]["radius_range"].is_null(),
        "{v}"
    );
    // A column that holds something else.
    for (column, role) in [("type", "the species"), ("y", "a coordinate")] {
        let e = fails(&[
            "convert",
            s(&d("sph.dump")),
            "-o",
            s(&d("x.mdlod")),
            "--radius-column",
            column,
        ]);
        assert!(
            e.contains(&format!(
                "column `{column}` holds {role}, not the particles' sizes"
            )),
            "{e}"
        );
    }
    let gsd = mdlod_datasets::gsd_sample_path("hoomd_mixture.gsd");
    let e = fails(&[
        "convert",
        s(&gsd),
        "-o",
        s(&d("g.mdlod")),
        "--radius-column",
        "h",
    ]);
    assert!(
        e.contains("--radius-column h names a column of a LAMMPS or XYZ dump"),
        "{e}"
    );
    // A batch converts again when the choice changes, and keeps its frames otherwise.
    let b = d("run.d");
    ok(&["batch", s(&gran), "-o", s(&b)]);
    let out = ok(&["batch", s(&gran), "-o", s(&b), "--no-sizes"]);
    assert!(out.contains("3 converted, 0 already done"), "{out}");
    let out = ok(&["batch", s(&gran), "-o", s(&b), "--no-sizes"]);
    assert!(out.contains("0 converted, 3 already done"), "{out}");
    let manifest = std::fs::read_to_string(b.join("dataset.json")).unwrap();
    assert!(manifest.contains("\"sizes\": \"none\""), "{manifest}");
    let out = ok(&["batch", s(&gran), "-o", s(&b)]);
    assert!(out.contains("3 converted, 0 already done"), "{out}");
    // Shards converted with other size columns are not merged.
    let sh = d("shards.d");
    ok(&["batch", s(&gran), "-o", s(&sh), "--shard", "0/2"]);
    ok(&[
        "batch",
        s(&gran),
        "-o",
        s(&sh),
        "--shard",
        "1/2",
        "--no-sizes",
    ]);
    let e = fails(&["batch", "--merge", s(&sh)]);
    assert!(e.contains("size column") && e.contains("none"), "{e}");
    // A file of a set that lacks the column named is refused before any frame is
    // converted.
    std::fs::write(d("set.1.dump"), &text).unwrap();
    std::fs::write(d("set.2.dump"), text.replace(" h d\n", " hh d\n")).unwrap();
    let e = fails(&[
        "batch",
        s(&d("set.1.dump")),
        s(&d("set.2.dump")),
        "-o",
        s(&d("set.d")),
        "--radius-column",
        "h",
    ]);
    assert!(
        e.contains("set.2.dump") && e.contains("no column `h` for --radius-column"),
        "{e}"
    );
    assert!(!d("set.d").join("frame-0.mdlod").exists());
}

/// What can go wrong with particles' own sizes, as a granular user meets it: a size of 0
/// is refused naming the type (as GSD's and MMPLD's are); sizes spanning decades are
/// noted; a `diameter` column beside the `radius` read is noted; a parallel run's
/// pieces that disagree on sizes are refused, whole or in chunks; an XYZ size property
/// of two numbers is refused; the density's iso-surface shows every grain, the largest
/// too; an output that is a symbolic link or a pipe is not replaced.
#[test]
fn particle_sizes_edge_cases_are_refused_or_noted() {
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| dir.path().join(n);
    let dump = |rows: &[(u32, f32, [f32; 3])], columns: &str| {
        let mut t = format!(
            "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{}\nITEM: BOX BOUNDS pp pp pp\n\
             -5 60\n-5 5\n-5 5\nITEM: ATOMS id type {columns} x y z\n",
            rows.len()
        );
        for (i, (t_, r, p)) in rows.iter().enumerate() {
            let size = if columns.contains("diameter") && !columns.contains("radius") {
                format!("{}", 2.0 * r)
            } else if columns.contains("diameter") {
                format!("{r} 3")
            } else {
                format!("{r}")
            };
            t.push_str(&format!(
                "{} {t_} {size} {} {} {}\n",
                i + 1,
                p[0],
                p[1],
                p[2]
            ));
        }
        t
    };
    let row = |r: f32, x: f32| (1u32, r, [x, 0.0, 0.0]);
    // A grain of size 0.
    std::fs::write(
        d("z.dump"),
        dump(&[row(0.0, 0.0), row(1.0, 10.0), row(2.0, 20.0)], "radius"),
    )
    .unwrap();
    let e = fails(&["convert", s(&d("z.dump")), "-o", s(&d("z.mdlod"))]);
    assert!(
        e.contains("z.dump: frame 0 (timestep 0), species 1: the file gives a particle of size 0")
            && e.contains(
                "--radius 1=R (every particle of it then takes R, those of sizes above 0 too"
            ),
        "{e}"
    );
    // A type whose particles all have size 0 beside one with sizes (an SPH dump's stars
    // beside its gas) converts once --radius gives it one, whole and in chunks, and
    // keeps the other type's own sizes.
    let mut rows: Vec<(u32, f32, [f32; 3])> = (0..6000)
        .map(|i| {
            let x = (i % 20) as f32 * 2.5;
            let y = ((i / 20) % 20) as f32 * 0.5 - 5.0;
            let z = (i / 400) as f32 * 0.6 - 4.5;
            if i % 3 == 0 {
                (2, 0.0, [x, y, z])
            } else {
                (1, 0.1 + 0.01 * (i % 7) as f32, [x, y, z])
            }
        })
        .collect();
    rows[1].1 = 0.1;
    std::fs::write(d("sph.dump"), dump(&rows, "radius")).unwrap();
    let e = fails(&["convert", s(&d("sph.dump")), "-o", s(&d("sph.mdlod"))]);
    assert!(
        e.contains("species 2: the file gives a particle of size 0"),
        "{e}"
    );
    let (sph, sph_file) = (d("sph.dump"), d("sph.mdlod"));
    for extra in [&[][..], &["--chunk-points", "5000"]] {
        let mut args = vec!["convert", s(&sph), "-o", s(&sph_file), "--radius", "2=0.05"];
        args.extend_from_slice(extra);
        ok(&args);
        let info = ok(&["info", s(&d("sph.mdlod"))]);
        assert!(
            info.contains("particles 0.100 to 0.160, each drawn at its own")
                && info.contains("radius 0.050"),
            "{extra:?}: {info}"
        );
        ok(&["verify", s(&d("sph.mdlod"))]);
    }
    // Below 0 is no size at all: refused at its line.
    std::fs::write(
        d("neg.dump"),
        dump(&[row(-1.0, 0.0), row(1.0, 10.0)], "radius"),
    )
    .unwrap();
    let e = fails(&[
        "convert",
        s(&d("neg.dump")),
        "-o",
        s(&d("neg.mdlod")),
        "--radius",
        "1=1",
    ]);
    assert!(
        e.contains("neg.dump:10: `radius` -1 is no particle size"),
        "{e}"
    );
    // Decades.
    std::fs::write(
        d("dec.dump"),
        dump(&[row(0.001, 0.0), row(100.0, 30.0)], "radius"),
    )
    .unwrap();
    let out = ok(&["convert", s(&d("dec.dump")), "-o", s(&d("dec.mdlod"))]);
    // Kept on a log scale (format 1.2), each within 1.1e-4 of its size: no note.
    let f = MdlodFile::open(d("dec.mdlod")).unwrap();
    let info = f.metadata().radius.unwrap();
    assert!(info.log && f.header().version_minor == 2, "{info:?}");
    let mut sizes: Vec<f32> = (0..2).map(|i| f.particle_radius(i)).collect();
    sizes.sort_by(f32::total_cmp);
    assert!(
        (sizes[0] / 0.001 - 1.0).abs() < 1.1e-4 && (sizes[1] / 100.0 - 1.0).abs() < 1.1e-4,
        "{sizes:?}"
    );
    assert!(!out.contains("note:"), "{out}");
    // Both columns: `radius` read, `diameter` noted.
    std::fs::write(
        d("both.dump"),
        dump(&[row(0.5, 0.0), row(1.0, 10.0)], "radius diameter"),
    )
    .unwrap();
    let out = ok(&["convert", s(&d("both.dump")), "-o", s(&d("both.mdlod"))]);
    assert!(
        out.contains("sizes are read from column `radius`; column `diameter` is left alone"),
        "{out}"
    );
    // Pieces of one run, one with sizes and one without.
    std::fs::write(
        d("gp.0.dump"),
        dump(&[row(0.5, 0.0), row(1.0, 10.0)], "radius"),
    )
    .unwrap();
    let plain = dump(&[row(0.5, 20.0), row(1.0, 30.0)], "radius").replace(" radius x", " x");
    let plain: String = plain
        .lines()
        .map(|l| {
            let f: Vec<&str> = l.split(' ').collect();
            if f.len() == 6 && !l.starts_with("ITEM") {
                format!("{} {} {} {} {}\n", f[0], f[1], f[3], f[4], f[5])
            } else {
                format!("{l}\n")
            }
        })
        .collect();
    std::fs::write(d("gp.1.dump"), plain).unwrap();
    let pieces = d("gp.%.dump");
    let e = fails(&["convert", s(&pieces), "-o", s(&d("gp.mdlod"))]);
    assert!(
        e.contains("gp.1.dump") && e.contains("gives no particle sizes"),
        "{e}"
    );
    let e = fails(&[
        "convert",
        s(&pieces),
        "-o",
        s(&d("gp.mdlod")),
        "--chunk-points",
        "2",
        "--root-points",
        "2",
        "--cluster-size",
        "2",
    ]);
    assert!(
        e.contains("per-particle sizes") && e.contains("share their columns"),
        "{e}"
    );
    // An XYZ size of two numbers.
    std::fs::write(
        d("r2.xyz"),
        "1\nProperties=species:S:1:pos:R:3:radius:R:2\nCu 0 0 0 1 2\n",
    )
    .unwrap();
    let e = fails(&["convert", s(&d("r2.xyz")), "-o", s(&d("r2.mdlod"))]);
    assert!(e.contains("`radius:R:2` is no particle size"), "{e}");
    // Five grains of one type, radii 0.5 to 1.5, 10 apart: the iso-surface shows five
    // blobs, the largest wider than the smallest (it lost the largest when the density's
    // reference radius was the type's mean).
    let rows: Vec<_> = (0..5)
        .map(|i| row(0.5 + 0.25 * i as f32, 10.0 * i as f32))
        .collect();
    std::fs::write(d("five.dump"), dump(&rows, "radius")).unwrap();
    ok(&["convert", s(&d("five.dump")), "-o", s(&d("five.mdlod"))]);
    ok(&[
        "render",
        s(&d("five.mdlod")),
        "-o",
        s(&d("iso.png")),
        "--mode",
        "iso",
        "--ortho",
        "--look-along",
        "0,0,-1",
        "--width",
        "400",
        "--height",
        "100",
        "--background",
        "black",
    ]);
    let (w, h, px) = read_png(&d("iso.png"));
    let lit = |x: u32| {
        px[4 * ((h / 2) * w + x) as usize..][..3]
            .iter()
            .any(|&c| c > 0)
    };
    let mut runs = Vec::new();
    let mut x = 0;
    while x < w {
        if lit(x) {
            let start = x;
            while x < w && lit(x) {
                x += 1;
            }
            runs.push(x - start);
        }
        x += 1;
    }
    assert_eq!(runs.len(), 5, "{runs:?}");
    // (Not in proportion: the density weighs a grain by its area, README.)
    assert!(runs[4] > runs[0], "{runs:?}");
    // Outputs that are no regular file.
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        std::os::unix::fs::symlink(d("five.mdlod"), d("link.mdlod")).unwrap();
        let e = fails(&["convert", s(&d("five.dump")), "-o", s(&d("link.mdlod"))]);
        assert!(
            e.contains("link.mdlod") && e.contains("symbolic link"),
            "{e}"
        );
        std::os::unix::fs::symlink(d("iso.png"), d("link.png")).unwrap();
        let e = fails(&[
            "render",
            s(&d("five.mdlod")),
            "-o",
            s(&d("link.png")),
            "--width",
            "8",
            "--height",
            "8",
        ]);
        assert!(e.contains("symbolic link"), "{e}");
        let fifo = d("pipe.mdlod");
        assert!(Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success());
        let e = fails(&["convert", s(&d("five.dump")), "-o", s(&fifo)]);
        assert!(
            e.contains("pipe.mdlod") && e.contains("not a regular file"),
            "{e}"
        );
        // The legend and the view file too, before anything is drawn (a legend was
        // written through a link, and into a pipe it blocked).
        std::os::unix::fs::symlink(d("iso.png"), d("legend.svg")).unwrap();
        let fifo_svg = d("pipe.svg");
        assert!(Command::new("mkfifo")
            .arg(&fifo_svg)
            .status()
            .unwrap()
            .success());
        for (option, path) in [
            ("--legend", d("legend.svg")),
            ("--legend", fifo_svg),
            ("--save-view", d("link.png")),
        ] {
            let e = fails(&[
                "render",
                s(&d("five.mdlod")),
                "-o",
                s(&d("new.png")),
                "--width",
                "8",
                "--height",
                "8",
                option,
                s(&path),
            ]);
            assert!(
                e.contains(option)
                    && (e.contains("symbolic link") || e.contains("not a regular file")),
                "{e}"
            );
            assert!(!d("new.png").exists());
        }
        // A batch's frame file and a movie's image that are links: refused before any
        // frame is converted or drawn.
        let run = d("run.d");
        std::fs::create_dir(&run).unwrap();
        let gran = lammps_sample_path("granular.dump");
        std::os::unix::fs::symlink(d("iso.png"), run.join("frame-4500.mdlod")).unwrap();
        let e = fails(&["batch", s(&gran), "-o", s(&run)]);
        assert!(
            e.contains("frame-4500.mdlod") && e.contains("symbolic link"),
            "{e}"
        );
        assert!(!run.join("frame-0.mdlod").exists());
        std::fs::remove_file(run.join("frame-4500.mdlod")).unwrap();
        ok(&["batch", s(&gran), "-o", s(&run)]);
        // A batch directory that is a link to a directory not there (a scratch space not
        // mounted): named, where creating it failed with "File exists".
        std::os::unix::fs::symlink(d("unmounted/run"), d("scratch.d")).unwrap();
        let e = fails(&["batch", s(&gran), "-o", s(&d("scratch.d"))]);
        assert!(
            e.contains("scratch.d: is a symbolic link to")
                && e.contains("unmounted/run, which does not exist"),
            "{e}"
        );
        std::fs::create_dir(d("movie")).unwrap();
        std::os::unix::fs::symlink(d("iso.png"), d("movie/f-2.png")).unwrap();
        let e = fails(&[
            "render",
            s(&run),
            "-o",
            s(&d("movie/f-%d.png")),
            "--width",
            "8",
            "--height",
            "8",
        ]);
        assert!(e.contains("f-2.png") && e.contains("symbolic link"), "{e}");
        assert!(!d("movie/f-0.png").exists());
        // `sample`: a directory that does not exist, and a file that is no S-NDF file.
        let e = fails(&[
            "sample",
            s(&d("five.mdlod")),
            "-o",
            s(&d("nodir/x.sndf")),
            "--width",
            "8",
            "--height",
            "8",
        ]);
        assert!(
            e.contains("the directory") && e.contains("does not exist"),
            "{e}"
        );
        let e = fails(&[
            "sample",
            s(&d("five.mdlod")),
            "-o",
            s(&d("five.dump")),
            "--width",
            "8",
            "--height",
            "8",
        ]);
        assert!(e.contains("exists and is no .sndf file"), "{e}");
        assert!(std::fs::symlink_metadata(&fifo)
            .unwrap()
            .file_type()
            .is_fifo());
    }
}

/// A movie whose first frame shows nothing (every particle of a hidden species, as a
/// deposition starts): the splats' exposure comes from the first frame that shows
/// anything, and the camera fits the frames that show the species, not the empty one's
/// box.
#[test]
fn a_movie_starting_with_nothing_shown_takes_its_look_from_the_frames_that_show_some() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("dep.lammpstrj");
    let mut text = String::new();
    for (step, deposited) in [(0, false), (100, true)] {
        text.push_str(&format!(
            "ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ATOMS\n420\nITEM: BOX BOUNDS pp pp pp\n\
             0 60\n0 60\n0 60\nITEM: ATOMS id type x y z\n"
        ));
        for i in 0..400 {
            let (x, y) = ((i % 20) as f32 * 3.0, (i / 20) as f32 * 3.0);
            text.push_str(&format!("{} 1 {x} {y} 1\n", i + 1));
        }
        // A small cluster of type 2 (type 1 before it lands).
        for i in 0..20 {
            let t = if deposited { 2 } else { 1 };
            let (x, y, z) = (30.0 + (i % 4) as f32, 30.0 + (i / 4) as f32, 20.0);
            text.push_str(&format!("{} {t} {x} {y} {z}\n", 401 + i));
        }
    }
    std::fs::write(&dump, text).unwrap();
    let d = dir.path().join("dep.d");
    ok(&[
        "batch",
        s(&dump),
        "-o",
        s(&d),
        "--radius",
        "1=1.28",
        "--radius",
        "2=1.44",
    ]);
    let last = dir.path().join("last.mdlod");
    let lpng = dir.path().join("l.png");
    ok(&[
        "convert",
        s(&dump),
        "-o",
        s(&last),
        "--radius",
        "1=1.28",
        "--radius",
        "2=1.44",
    ]);
    let exposure = |out: &str| {
        let at = out.find("exposure ").unwrap() + "exposure ".len();
        out[at..]
            .split(|c: char| c.is_whitespace() || c == ',' || c == ';')
            .next()
            .unwrap()
            .to_string()
    };
    let size = ["--width", "32", "--height", "24", "--hide-species", "1"];
    let movie = dir.path().join("m-%d.png");
    let mut args = vec!["render", s(&d), "-o", s(&movie), "--mode", "splat"];
    args.extend(size);
    let out = ok(&args);
    let mut args = vec!["render", s(&last), "-o", s(&lpng), "--mode", "splat"];
    args.extend(size);
    let single = ok(&args);
    assert_eq!(exposure(&out), exposure(&single), "{out}\n{single}");
    // The camera: the deposited cluster's, as the last frame alone fits it.
    let (mv, sv) = (
        dir.path().join("movie.json"),
        dir.path().join("single.json"),
    );
    let mut args = vec!["render", s(&d), "-o", s(&movie), "--save-view", s(&mv)];
    args.extend(size);
    ok(&args);
    let mut args = vec!["render", s(&last), "-o", s(&lpng), "--save-view", s(&sv)];
    args.extend(size);
    ok(&args);
    let view = |p: &Path| {
        serde_json::from_str::<serde_json::Value>(&std::fs::read_to_string(p).unwrap()).unwrap()
    };
    let (m, s1) = (view(&mv), view(&sv));
    assert_eq!(m["target"], s1["target"]);
    let (dm, ds) = (
        m["distance"].as_f64().unwrap(),
        s1["distance"].as_f64().unwrap(),
    );
    assert!((dm - ds).abs() < 1e-3 * ds, "movie {dm}, single {ds}");
}

/// Options that cannot mean anything here are refused or explained: `--fit-all` with a
/// view file that fits nothing, `--log-scale` of an attribute already a logarithm, a log
/// scale of signed values, a range that misses every value.
#[test]
fn log_scales_ranges_and_fits_that_mean_nothing_are_refused_or_explained() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("v.lammpstrj");
    let mut text = String::from(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n100\nITEM: BOX BOUNDS pp pp pp\n0 20\n0 20\n\
         0 2\nITEM: ATOMS id type x y z vx rho\n",
    );
    for i in 0..100 {
        let (x, y) = ((i % 10) as f32 * 2.0, (i / 10) as f32 * 2.0);
        text.push_str(&format!(
            "{} 1 {x} {y} 1 {} {:e}\n",
            i + 1,
            i as f32 / 10.0 - 3.0,
            10f32.powi(i % 7 - 3)
        ));
    }
    std::fs::write(&dump, text).unwrap();
    let (vx, rho) = (dir.path().join("vx.mdlod"), dir.path().join("rho.mdlod"));
    ok(&["convert", s(&dump), "-o", s(&vx), "--attribute", "vx"]);
    ok(&[
        "convert",
        s(&dump),
        "-o",
        s(&rho),
        "--attribute",
        "rho",
        "--attribute-log10",
    ]);
    let png = dir.path().join("x.png");
    fn run<'a>(file: &'a Path, png: &'a Path, extra: &[&'a str]) -> Vec<&'a str> {
        let mut args = vec![
            "render",
            s(file),
            "-o",
            s(png),
            "--width",
            "24",
            "--height",
            "18",
        ];
        args.extend(extra);
        args
    }
    let e = fails(&run(&rho, &png, &["--colour-map", "magma", "--log-scale"]));
    assert!(
        e.contains("already a logarithm") && e.contains("log10(rho)"),
        "{e}"
    );
    // Splats lit by a logarithm light by its quantity, the projected rho, projection or
    // not (the clusters keep the logarithm of their mean value).
    for extra in [&[][..], &["--colour-map", "viridis", "--log-scale"]] {
        let mut args = vec!["--mode", "splat", "--intensity", "attribute"];
        args.extend_from_slice(extra);
        let out = ok(&run(&rho, &png, &args));
        if !extra.is_empty() {
            assert!(
                out.contains("the image's light (the projected rho)"),
                "{out}"
            );
        }
    }
    let out = ok(&run(&vx, &png, &["--colour-map", "viridis", "--log-scale"]));
    assert!(
        out.contains("note: vx takes values below 0 (down to -3)"),
        "{out}"
    );
    // Of the particles drawn: with those below -1 hidden, down to -1; with all below 0
    // hidden, nothing to say.
    for (hide, said) in [
        (
            "--hide-attribute=:-1.05",
            Some("note: vx takes values below 0 (down to -1)"),
        ),
        ("--hide-attribute=:0", None),
    ] {
        let out = ok(&run(
            &vx,
            &png,
            &["--colour-map", "viridis", "--log-scale", hide],
        ));
        match said {
            Some(note) => assert!(out.contains(note), "{out}"),
            None => assert!(!out.contains("takes values below 0"), "{out}"),
        }
    }
    // No value above 0: the scale stays linear, said once, with no note on a log scale.
    let out = ok(&run(
        &vx,
        &png,
        &[
            "--colour-map",
            "viridis",
            "--log-scale",
            "--attribute-range",
            "-3:-1",
        ],
    ));
    assert!(
        out.contains("linear (--log-scale left unused: no value of the range is above 0")
            && !out.contains("on a log scale"),
        "{out}"
    );
    let out = ok(&run(
        &rho,
        &png,
        &["--colour-map", "viridis", "--attribute-range", "4:5"],
    ));
    assert!(
        out.contains("misses the file's values (log10(rho) from -3 to 3)"),
        "{out}"
    );
    // Values typed for logarithms stand for no number single precision holds.
    let e = fails(&run(
        &rho,
        &png,
        &["--colour-map", "viridis", "--attribute-range", "100:1000"],
    ));
    assert!(e.contains("100 stands for 10^100"), "{e}");
    // A view file with its target and distance fits nothing.
    let view = dir.path().join("v.json");
    ok(&run(&vx, &png, &["--save-view", s(&view)]));
    let e = fails(&run(&vx, &png, &["--view", s(&view), "--fit-all"]));
    assert!(e.contains("--fit-all has no effect with --view"), "{e}");
}

/// Outputs get the permissions any new file gets under the user's umask (private under
/// `umask 077`, group-writable under `umask 002`), not a fixed 0644.
#[cfg(unix)]
#[test]
fn outputs_honour_the_umask() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let input = lammps_sample_path("cu_melt.custom.dump");
    let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
    for (umask, want) in [("077", 0o600), ("002", 0o664)] {
        let file = dir.path().join(format!("u{umask}.mdlod"));
        let png = dir.path().join(format!("u{umask}.png"));
        let batch = dir.path().join(format!("b{umask}"));
        std::fs::create_dir(&batch).unwrap();
        let bin = env!("CARGO_BIN_EXE_mdlod");
        let script = format!(
            "umask {umask} && {bin} convert {} -o {} && {bin} render {} -o {} --width 32 \
             --height 24 && {bin} batch {} -o {}",
            s(&input),
            s(&file),
            s(&file),
            s(&png),
            s(&input),
            s(&batch)
        );
        let out = Command::new("sh").args(["-c", &script]).output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        for p in [
            &file,
            &png,
            &batch.join("dataset.json"),
            &batch.join("frame-0.mdlod"),
        ] {
            assert_eq!(mode(p), want, "{} under umask {umask}", p.display());
        }
    }
}

/// The batch summary counts the frames left out as duplicate timesteps apart from the
/// frames to convert ("3 frames in the inputs" of 4 read as a miscount).
#[test]
fn a_batch_summary_counts_duplicate_timesteps_apart() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(lammps_sample_path("cu_melt.custom.dump")).unwrap();
    let start = text.find("ITEM: TIMESTEP").unwrap();
    let end = start + text[start..].find("ITEM: TIME\n").unwrap();
    let frame = &text[start..end];
    let step = frame.lines().nth(1).unwrap();
    let dump: String = [0, 100, 100, 200]
        .iter()
        .map(|t| {
            frame.replacen(
                &format!("ITEM: TIMESTEP\n{step}\n"),
                &format!("ITEM: TIMESTEP\n{t}\n"),
                1,
            )
        })
        .collect();
    let input = dir.path().join("r.dump");
    std::fs::write(&input, dump).unwrap();
    let out = ok(&[
        "batch",
        s(&input),
        "-o",
        s(&dir.path().join("b")),
        "--duplicate-timesteps",
        "last",
    ]);
    assert!(
        out.contains("3 frames in the inputs (1 more left out as duplicate timesteps): "),
        "{out}"
    );
}

/// A working directory that cannot be made names the option that chose its place.
#[test]
fn a_working_directory_that_cannot_be_made_names_its_option() {
    let dir = tempfile::tempdir().unwrap();
    let input = lammps_sample_path("cu_melt.custom.dump");
    let out = dir.path().join("x.mdlod");
    let missing = dir.path().join("none").join("deeper");
    let e = fails(&[
        "convert",
        s(&input),
        "-o",
        s(&out),
        "--temp-dir",
        s(&missing),
    ]);
    assert!(
        e.contains("cannot create a working directory in") && e.contains("(the --temp-dir given)"),
        "{e}"
    );
    let e = fails(&[
        "batch",
        s(&input),
        "-o",
        s(&dir.path().join("b")),
        "--temp-dir",
        s(&missing),
    ]);
    assert!(e.contains("(the --temp-dir given)"), "{e}");
}

/// A negative memory limit gets the size parser's answer, not clap's "unexpected
/// argument '-1'"; one above the machine's memory is noted.
#[test]
fn memory_limits_past_the_machine_or_below_zero_are_said() {
    let dir = tempfile::tempdir().unwrap();
    let input = lammps_sample_path("cu_melt.custom.dump");
    let out = dir.path().join("m.mdlod");
    for cmd in ["convert", "batch"] {
        let target = if cmd == "batch" {
            dir.path().join("b")
        } else {
            out.clone()
        };
        let e = fails(&[cmd, s(&input), "-o", s(&target), "--memory-limit", "-1G"]);
        assert!(
            e.contains("\"-1G\" is not a size such as 512M"),
            "{cmd}: {e}"
        );
        let said = ok(&[
            cmd,
            s(&input),
            "-o",
            s(&target),
            "--memory-limit",
            "100000T",
        ]);
        assert!(
            said.contains("note: --memory-limit 102400000.0 GiB is above the"),
            "{cmd}: {said}"
        );
    }
}

/// A two-dimensional LAMMPS run's dump (`dimension 2`: every z 0, the box's z from -0.5
/// to 0.5): `frames` frames of a 40 × 25 layer.
fn flat_dump(path: &Path, frames: u32) {
    let mut text = String::new();
    for f in 0..frames {
        text.push_str(&format!(
            "ITEM: TIMESTEP\n{}\nITEM: NUMBER OF ATOMS\n1000\nITEM: BOX BOUNDS pp pp pp\n\
             0 44\n0 27.5\n-0.5 0.5\nITEM: ATOMS id type x y z\n",
            f * 100
        ));
        for i in 0..1000u32 {
            let (x, y) = (f64::from(i % 40) * 1.1, f64::from(i / 40) * 1.1);
            text.push_str(&format!("{} {} {x} {y} 0\n", i + 1, 1 + i % 2));
        }
    }
    std::fs::write(path, text).unwrap();
}

#[test]
fn two_dimensional_data_is_seen_square_on_by_default() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("flat.lammpstrj");
    flat_dump(&dump, 2);
    let file = dir.path().join("flat.mdlod");
    ok(&[
        "convert",
        s(&dump),
        "-o",
        s(&file),
        "--radius",
        "1=0.5",
        "--radius",
        "2=0.5",
    ]);
    let batch = dir.path().join("traj");
    ok(&[
        "batch",
        s(&dump),
        "-o",
        s(&batch),
        "--radius",
        "1=0.5",
        "--radius",
        "2=0.5",
    ]);
    let angles = |view: &Path| {
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(view).unwrap()).unwrap();
        (
            v["azimuth_deg"].as_f64().unwrap(),
            v["elevation_deg"].as_f64().unwrap(),
        )
    };
    let size = ["--width", "64", "--height", "48"];
    for (case, input, out, extra) in [
        ("a still", &file, "still.png", vec![]),
        ("a still, zoomed", &file, "still.png", vec!["--zoom", "2"]),
        ("a movie", &batch, "movie/f-%03d.png", vec![]),
    ] {
        let view = dir.path().join("view.json");
        let png = dir.path().join(out);
        let mut args = vec!["render", s(input), "-o", s(&png), "--save-view", s(&view)];
        args.extend(size);
        args.extend(extra);
        ok(&args);
        let (azimuth, elevation) = angles(&view);
        assert!(
            (elevation - 90.0).abs() < 1e-3 && (azimuth + 90.0).abs() < 1e-3,
            "{case}: ({azimuth}, {elevation})"
        );
    }
    // `info` says so.
    let text = ok(&["info", s(&file)]);
    assert!(
        text.contains("flat         every particle's centre at one z"),
        "{text}"
    );
    let json: serde_json::Value = serde_json::from_str(&ok(&["info", s(&file), "--json"])).unwrap();
    assert_eq!(json["flat_axis"], "z");
    // An angle given is kept: the other takes the three-dimensional default.
    let view = dir.path().join("view.json");
    let png = dir.path().join("one.png");
    let mut args = vec!["render", s(&file), "-o", s(&png), "--save-view", s(&view)];
    args.extend(size);
    args.extend(["--azimuth", "10"]);
    ok(&args);
    assert_eq!(angles(&view), (10.0, 20.0));
}

/// `sample` says the screen error its cut reached and what stopped it short, as
/// `render` does: a budget below the cut the error asks for.
#[test]
fn sample_says_the_error_reached_and_the_budget_that_stopped_it() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("c.lammpstrj");
    generate(&["crater", "-n", "20000"], &input);
    let file = dir.path().join("m.mdlod");
    ok(&["convert", s(&input), "-o", s(&file)]);
    let coarsest = MdlodFile::open(&file).unwrap().levels()[1].point_count;
    assert!(coarsest < 5000, "{coarsest}");
    let out_file = dir.path().join("m.sndf");
    let sample = |extra: &[&str]| {
        ok(&[
            &["sample", s(&file), "-o", s(&out_file)][..],
            &["--width", "48", "--height", "32", "--iterations", "1"],
            extra,
        ]
        .concat())
    };
    let fine = sample(&["--screen-error", "0"]);
    assert!(fine.contains("error 0.00 px,"), "{fine}");
    let limited = sample(&["--screen-error", "0", "--budget", "5000"]);
    assert!(
        limited.contains("(point budget of 5000 reached: a larger --budget refines further)")
            && !limited.contains("error 0.00 px"),
        "{limited}"
    );
    // Below the coarsest level: the whole data set one sphere, and the budget that
    // refines it.
    // A --min-samples the image size already gives says so.
    let already = ok(&[
        "sample",
        s(&file),
        "-o",
        s(&out_file),
        "--width",
        "48",
        "--height",
        "32",
        "--iterations",
        "64",
        "--min-samples",
        "1",
    ]);
    assert!(
        already.contains(
            "--min-samples 1: every sphere gets that many samples at the image size already"
        ),
        "{already}"
    );
    let hidden = sample(&["--hide-species", "1"]);
    assert!(
        hidden.contains("note: every species is hidden: nothing is sampled"),
        "{hidden}"
    );
    let one = sample(&["--budget", "40"]);
    assert!(
        one.contains(&format!(
            "so the whole data set is one sphere; a budget of {coarsest} or more refines"
        )),
        "{one}"
    );
}

/// An iso-value no packing of the spheres reaches draws the background only, and says
/// so; one the data reaches draws a surface and says nothing of the kind.
#[test]
fn an_iso_value_no_ray_meets_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let frame = converted(dir.path(), "cu_melt.custom.dump");
    let png = dir.path().join("iso.png");
    let iso = |value: &str, extra: &[&str]| {
        ok(&[
            &[
                "render",
                s(&frame),
                "-o",
                s(&png),
                "--width",
                "64",
                "--height",
                "48",
                "--mode",
                "iso",
                "--iso-value",
                value,
            ][..],
            extra,
        ]
        .concat())
    };
    let none = iso("5", &[]);
    assert!(
        none.contains("note: no ray meets a volume fraction of 5"),
        "{none}"
    );
    let (_, _, px) = read_png(&png);
    assert!(px.chunks(4).all(|p| p == &px[..4]));
    let some = iso("0.3", &[]);
    assert!(!some.contains("no ray meets"), "{some}");
    let (_, _, px) = read_png(&png);
    assert!(px.chunks(4).any(|p| p != &px[..4]));
    // From inside the surface every pixel is the surface's one colour, not the
    // background: nothing is said.
    let inside = iso("0.3", &["--ortho", "--zoom", "1e7"]);
    let (_, _, px) = read_png(&png);
    assert!(px.chunks(4).all(|p| p == &px[..4]) && px[..3] != [255, 255, 255]);
    assert!(!inside.contains("no ray meets"), "{inside}");
}

/// A movie of a batch directory whose frame file was deleted names the manifest, the
/// frame and the remedy, instead of the system's bare "No such file"; one whose frame
/// file was damaged names the frame and the remedy too.
#[test]
fn a_movie_missing_a_frame_file_says_which_and_how_to_get_it_back() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("d.lammpstrj");
    generate(&["droplets", "-n", "500", "--frames", "3"], &input);
    let d = dir.path().join("d");
    ok(&["batch", s(&input), "-o", s(&d)]);
    std::fs::remove_file(d.join("frame-100.mdlod")).unwrap();
    let movie = dir.path().join("m/f-%d.png");
    let e = fails(&[
        "render",
        s(&d),
        "-o",
        s(&movie),
        "--width",
        "32",
        "--height",
        "24",
    ]);
    assert!(
        e.contains("lists frame-100.mdlod (timestep 100), but the file is missing")
            && e.contains("rerun the batch"),
        "{e}"
    );
    // As it says: the rerun converts it again, and the movie renders.
    ok(&["batch", s(&input), "-o", s(&d)]);
    let render = [
        "render",
        s(&d),
        "-o",
        s(&movie),
        "--width",
        "32",
        "--height",
        "24",
    ];
    ok(&render);
    // A frame file damaged since (bytes of its particles' positions changed): the
    // error names the frame and says what mends it, which mends it.
    let frame = d.join("frame-200.mdlod");
    let f = mdlod_format::MdlodFile::open(&frame).unwrap();
    let positions = *f.sections().iter().rfind(|e| e.kind == 4).unwrap();
    drop(f);
    let mut bytes = std::fs::read(&frame).unwrap();
    let at = (positions.offset + positions.length / 2) as usize;
    bytes[at..at + 64].iter_mut().for_each(|b| *b ^= 0x5a);
    std::fs::write(&frame, bytes).unwrap();
    let e = fails(&render);
    assert!(
        e.contains("frame 2 of 0-2 (timestep 200) is damaged: while its dump")
            && e.contains("d.lammpstrj is at hand, delete")
            && e.contains("and rerun `mdlod batch` with the same inputs")
            && e.contains("checksum mismatch"),
        "{e}"
    );
    std::fs::remove_file(&frame).unwrap();
    ok(&["batch", s(&input), "-o", s(&d)]);
    ok(&render);
}

/// Messages a newcomer meets: a style naming an element in a file of type numbers says
/// how to name the type; a view file that does not exist is named as the view file.
#[test]
fn render_names_type_numbers_and_missing_view_files_plainly() {
    let dir = tempfile::tempdir().unwrap();
    let frame = converted(dir.path(), "cu_melt.custom.dump");
    let png = dir.path().join("x.png");
    let e = fails(&[
        "render",
        s(&frame),
        "-o",
        s(&png),
        "--species-colour",
        "Cu=red",
    ]);
    assert!(
        e.contains("no species named \"Cu\" (the file's species are named 1)")
            && e.contains("name the type here (1), or convert with --species-name 1=Cu"),
        "{e}"
    );
    // One species styled twice by one option: refused, not the last taken silently.
    let e = fails(&[
        "render",
        s(&frame),
        "-o",
        s(&png),
        "--species-colour",
        "1=#00ff00",
        "--species-colour",
        "1=#ff0000",
    ]);
    assert!(
        e.contains("--species-colour names \"1\" twice (\"1=#00ff00\", then \"1=#ff0000\")"),
        "{e}"
    );
    let missing = dir.path().join("nofile.json");
    let e = fails(&["render", s(&frame), "-o", s(&png), "--view", s(&missing)]);
    assert!(
        e.contains(&format!("view file {}: cannot read it", missing.display())),
        "{e}"
    );
    assert!(!png.exists());
}

/// S-NDFs past the adapter's largest buffer are refused before any is allocated, naming
/// the bins that fit.
#[test]
fn sndfs_past_the_largest_buffer_name_the_bins_that_fit() {
    let dir = tempfile::tempdir().unwrap();
    let frame = converted(dir.path(), "cu_melt.custom.dump");
    let out = dir.path().join("x.sndf");
    // 2048×1152 texels of 32×32 bins: 38 GB.
    let e = fails(&[
        "sample",
        s(&frame),
        "-o",
        s(&out),
        "--width",
        "2048",
        "--height",
        "1152",
        "--bins",
        "32",
        "--iterations",
        "1",
    ]);
    let fits: u32 = e
        .split("bins fit (--bins ")
        .nth(1)
        .and_then(|rest| rest.split(')').next())
        .and_then(|b| b.parse().ok())
        .unwrap_or_else(|| panic!("{e}"));
    assert!((1..32).contains(&fits), "{e}");
    assert!(
        e.contains("more than one buffer of this adapter holds"),
        "{e}"
    );
    assert!(!out.exists());
}

/// A movie's summary of radii changing over the frames leaves out hidden species: B
/// alone in frame 0 is boron, with the element's radius, and beside the label A after,
/// a label with the default radius.
#[test]
fn a_movie_says_nothing_of_the_radii_of_hidden_species() {
    let dir = tempfile::tempdir().unwrap();
    let xyz = dir.path().join("dep.xyz");
    let mut text = String::from("3\nTimestep=0\n");
    for i in 0..3 {
        text += &format!("B {i} 0 0\n");
    }
    text += "4\nTimestep=100\n";
    for i in 0..3 {
        text += &format!("B {i} 0 0\n");
    }
    text += "A 0 2 0\n";
    std::fs::write(&xyz, text).unwrap();
    let d = dir.path().join("d");
    ok(&["batch", s(&xyz), "-o", s(&d)]);
    let movie = dir.path().join("m/f-%d.png");
    let args = [
        "render",
        s(&d),
        "-o",
        s(&movie),
        "--width",
        "32",
        "--height",
        "24",
    ];
    // Shown, B keeps one look (its later frames') throughout; hidden, its files' own
    // radii, which differ, are no concern of the picture's.
    let shown = ok(&args);
    assert!(shown.contains("drawn with its one look (B)"), "{shown}");
    let hidden = ok(&[&args[..], &["--hide-species", "B"]].concat());
    assert!(!hidden.contains("radii change"), "{hidden}");
    assert!(!hidden.contains("every species is hidden"), "{hidden}");
    let all = ok(&[&args[..], &["--hide-species", "B", "--hide-species", "A"]].concat());
    assert!(
        all.contains("note: every species is hidden: the images show the background only"),
        "{all}"
    );
}

/// Hostile paths and files in place of inputs: a device or a FIFO is refused before it
/// is opened (a FIFO blocked every reader, /dev/zero as a view file or manifest grew the
/// process without bound); a view file that is a list, or whose number overflows single
/// precision, is named as such; a manifest whose frames' timesteps disagree with their
/// files is refused.
#[test]
fn devices_fifos_and_odd_view_files_are_refused_plainly() {
    let dir = tempfile::tempdir().unwrap();
    let frame = converted(dir.path(), "cu_melt.custom.dump");
    let png = dir.path().join("x.png");
    let size = ["--width", "32", "--height", "24"];
    let render =
        |extra: &[&str]| fails(&[&["render", s(&frame), "-o", s(&png)][..], &size, extra].concat());
    let e = render(&["--view", "/dev/zero"]);
    assert!(
        e.contains("view file /dev/zero: cannot read it: not a regular file"),
        "{e}"
    );
    let list = dir.path().join("list.json");
    std::fs::write(&list, r#"[1, "orthographic", 45, 10]"#).unwrap();
    let e = render(&["--view", s(&list)]);
    assert!(e.contains("a view file is a JSON object"), "{e}");
    let huge = dir.path().join("huge.json");
    std::fs::write(&huge, "{\"version\": 1,\n\"azimuth_deg\": 1e300}").unwrap();
    let e = render(&["--view", s(&huge)]);
    assert!(
        e.contains("azimuth_deg inf (not a finite number in single precision"),
        "{e}"
    );
    let fifo = dir.path().join("fifo");
    if std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .is_ok_and(|st| st.success())
    {
        // Each refused at once (a reader opening it would wait for a writer forever).
        for args in [
            vec!["info", s(&fifo)],
            vec!["verify", s(&fifo)],
            vec!["shade", s(&fifo), "-o", s(&png)],
            vec!["render", s(&frame), "-o", s(&png), "--view", s(&fifo)],
        ] {
            let e = fails(&args);
            assert!(e.contains("not a regular file"), "{args:?}: {e}");
        }
    }
    // A manifest listing each frame as the other's timestep.
    let input = dir.path().join("d.lammpstrj");
    generate(&["droplets", "-n", "300", "--frames", "2"], &input);
    let d = dir.path().join("d");
    ok(&["batch", s(&input), "-o", s(&d)]);
    let manifest = d.join("dataset.json");
    let text = std::fs::read_to_string(&manifest)
        .unwrap()
        .replace("frame-0.mdlod", "frame-X.mdlod")
        .replace("frame-100.mdlod", "frame-0.mdlod")
        .replace("frame-X.mdlod", "frame-100.mdlod");
    std::fs::write(&manifest, text).unwrap();
    let movie = dir.path().join("m/f-%d.png");
    let e = fails(&[&["render", s(&d), "-o", s(&movie)][..], &size].concat());
    assert!(
        e.contains("lists frame-100.mdlod as timestep 0, but the file holds timestep 100"),
        "{e}"
    );
    // A frame replaced by another conversion of the same timestep: the manifest's
    // checksum (the file's section table's) tells, in a movie as in `verify`.
    let d = dir.path().join("r");
    ok(&["batch", s(&input), "-o", s(&d)]);
    let frame = d.join("frame-100.mdlod");
    ok(&[
        "convert",
        s(&input),
        "--frame",
        "1",
        "-o",
        s(&frame),
        "--radius",
        "1=0.7",
    ]);
    let e = fails(&[&["render", s(&d), "-o", s(&movie)][..], &size].concat());
    assert!(
        e.contains("lists frame-100.mdlod (timestep 100) with checksum")
            && e.contains("it was replaced after the batch wrote the manifest"),
        "{e}"
    );
    // A time edited in the manifest labels the images wrongly: `verify` and a movie
    // refuse it.
    let d = dir.path().join("t");
    ok(&["batch", s(&input), "-o", s(&d)]);
    let manifest = d.join("dataset.json");
    let mut m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&manifest).unwrap()).unwrap();
    m["frames"][1]["time"] = 99.0.into();
    std::fs::write(&manifest, m.to_string()).unwrap();
    let run = mdlod(&["verify", s(&d)]);
    let out =
        String::from_utf8_lossy(&run.stdout).to_string() + &String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success(), "{out}");
    assert!(
        out.contains("the file's time is not the one the manifest lists"),
        "{out}"
    );
    let e = fails(&[&["render", s(&d), "-o", s(&movie)][..], &size].concat());
    assert!(
        e.contains("lists frame-100.mdlod with time 99, but the file holds"),
        "{e}"
    );
}

/// The spheres and S-NDF modes take a light (direction in view space, colour), the
/// ambient, diffuse and highlight weights, and the BRDF; other modes refuse them.
#[test]
fn render_takes_a_light_and_its_reflectance() {
    let dir = tempfile::tempdir().unwrap();
    let xyz = dir.path().join("one.xyz");
    std::fs::write(&xyz, "1\nProperties=species:S:1:pos:R:3\nAr 0 0 0\n").unwrap();
    let file = dir.path().join("one.mdlod");
    ok(&["convert", s(&xyz), "-o", s(&file)]);
    let png = dir.path().join("lit.png");
    // The summed (r, g, b) of the image's left and right halves.
    let halves = |extra: &[&str]| {
        ok(&[
            &[
                "render",
                s(&file),
                "-o",
                s(&png),
                "--width",
                "64",
                "--height",
                "64",
            ][..],
            &["--ortho", "--background", "#000000"],
            extra,
        ]
        .concat());
        let (w, _, px) = read_png(&png);
        let mut sums = [[0u64; 3]; 2];
        for (i, p) in px.chunks(4).enumerate() {
            let half = usize::from(i as u32 % w >= w / 2);
            for k in 0..3 {
                sums[half][k] += u64::from(p[k]);
            }
        }
        sums
    };
    for mode in ["spheres", "sndf"] {
        let right = halves(&["--mode", mode, "--light", "1,0,0.3"]);
        assert!(2 * right[1][0] > 3 * right[0][0], "{mode}: {right:?}");
        let left = halves(&["--mode", mode, "--light", "-1,0,0.3:#ff0000"]);
        assert!(2 * left[0][0] > 3 * left[1][0], "{mode}: {left:?}");
        // A red light adds no green nor blue: those are the ambient's on both sides.
        for k in [1, 2] {
            let (a, b) = (left[0][k] as f64, left[1][k] as f64);
            assert!((a - b).abs() <= 0.02 * a.max(b), "{mode}: {left:?}");
        }
    }
    // Only the ambient: both halves alike.
    let flat = halves(&["--ambient", "1", "--diffuse", "0", "--brdf", "lambert"]);
    let (a, b) = (flat[0][0] as f64, flat[1][0] as f64);
    assert!((a - b).abs() < 0.05 * a.max(b), "{flat:?}");
    let render =
        |extra: &[&str]| fails(&[&["render", s(&file), "-o", s(&png)][..], extra].concat());
    for (extra, says) in [
        (
            vec!["--brdf", "lambert", "--specular", "0.5"],
            "--specular has no effect with --brdf lambert",
        ),
        (
            vec!["--ambient", "-1"],
            "--ambient -1 (must be a finite number, 0 or more)",
        ),
        (
            vec!["--mode", "splat", "--light", "1,0,0"],
            "--light has no effect with --mode splat",
        ),
        (
            vec!["--light", "0,0,0"],
            "--light: light \"0,0,0\": the direction must be",
        ),
    ] {
        let e = render(&extra);
        assert!(e.contains(says), "{extra:?}: {e}");
    }
}

/// `batch --keep-going`: the bad frame said on stderr with its place, the others
/// converted and counted, and an error status at the end saying what a rerun does.
#[test]
fn a_batch_that_keeps_going_ends_with_an_error_naming_the_bad_frame() {
    let dir = tempfile::tempdir().unwrap();
    let good = std::fs::read_to_string(lammps_sample_path("cu_melt.custom.dump")).unwrap();
    let at = good.match_indices("ITEM: ATOMS").nth(4).unwrap().0;
    let line = at + good[at..].find('\n').unwrap() + 1;
    let end = line + good[line..].find('\n').unwrap();
    let mut fields: Vec<&str> = good[line..end].split(' ').collect();
    fields[4] = "inf";
    let src = dir.path().join("bad.dump");
    std::fs::write(
        &src,
        format!("{}{}{}", &good[..line], fields.join(" "), &good[end..]),
    )
    .unwrap();
    let out = dir.path().join("out");
    let run = mdlod(&["batch", s(&src), "-o", s(&out), "--keep-going"]);
    assert!(!run.status.success());
    let (stdout, stderr) = (
        String::from_utf8(run.stdout).unwrap(),
        String::from_utf8(run.stderr).unwrap(),
    );
    assert!(
        stdout.contains("5 converted, 0 already done, 1 failed (said above; not in the manifest)"),
        "{stdout}"
    );
    assert!(
        stderr.contains("bad.dump: frame 4 (timestep 400) not converted: ")
            && stderr.contains("`inf` is not a finite number")
            && stderr
                .contains("1 frame could not be converted (--keep-going converted the others)"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"));
    // Without --keep-going, one thread: the frames before the bad one converted, and
    // `to_convert` the frames still missing, as an interrupted batch counts them.
    let stopped = dir.path().join("stopped");
    let run = mdlod(&[
        "batch",
        s(&src),
        "-o",
        s(&stopped),
        "--threads",
        "1",
        "--json",
    ]);
    assert!(!run.status.success());
    let v: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    assert_eq!(
        (&v["ok"], &v["converted"], &v["to_convert"]),
        (&false.into(), &4.into(), &2.into()),
        "{v}"
    );
    // An input that holds no dump fails too, and the counts add up (6 frames and it).
    let log = dir.path().join("log.lammps");
    std::fs::write(&log, "LAMMPS (29 Aug 2024)\nunits metal\n").unwrap();
    let other = dir.path().join("other");
    let run = mdlod(&["batch", s(&src), s(&log), "-o", s(&other), "--keep-going"]);
    let stdout = String::from_utf8(run.stdout).unwrap();
    assert!(
        stdout.contains("7 frames in the inputs: 5 converted, 0 already done, 2 failed"),
        "{stdout}"
    );
    // A movie of the directory says which frame it lacks, as a jump in time would not.
    let movie = dir.path().join("m-%d.png");
    let mut args = vec!["render", s(&out), "-o", s(&movie)];
    args.extend(["--width", "64", "--height", "48"]);
    let rendered = ok(&args);
    assert!(
        rendered.contains(
            "note: the batch left out 1 frame that failed to convert (timestep 400): the images \
             are numbered without them"
        ) && rendered.contains("says why the frame failed, and a rerun of the batch converts it"),
        "{rendered}"
    );
    // (Said once.)
    assert_eq!(rendered.matches("timestep 400").count(), 1, "{rendered}");
    let info = ok(&["info", s(&out)]);
    assert!(
        info.contains("failed       1 frame the batch could not convert: timestep 400"),
        "{info}"
    );
    // So does one of a batch yet to finish (here: a manifest that expects one more).
    let manifest = out.join("dataset.json");
    let mut m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&manifest).unwrap()).unwrap();
    m.as_object_mut().unwrap().remove("failed");
    m["expected_frames"] = 6.into();
    std::fs::write(&manifest, m.to_string()).unwrap();
    let rendered = ok(&args);
    assert!(
        rendered.contains(
            "note: the batch lists 5 of the 6 frames its run is to convert (still running"
        ) && !rendered.contains("could not convert"),
        "{rendered}"
    );
    let info = ok(&["info", s(&out)]);
    assert!(
        info.contains("missing      1 of the 6 frames the run is to convert"),
        "{info}"
    );
}

/// `--attribute` repeated keeps several columns in one file (format 1.2): `info` lists
/// them, render's `--attribute NAME` colours by any (as a file of that column alone
/// draws it), an unknown name lists the file's, and a batch reconverts frames whose
/// columns changed and keeps those whose did not.
#[test]
fn several_attributes_in_one_file_colour_by_any() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("c.lammpstrj");
    generate(&["crater", "-n", "3000", "--frames", "2"], &dump);
    let both = dir.path().join("both.mdlod");
    ok(&[
        "convert",
        s(&dump),
        "-o",
        s(&both),
        "--attribute",
        "c_ke",
        "--attribute",
        "z",
    ]);
    let info = ok(&["info", s(&both)]);
    assert!(
        info.contains("format 1.2")
            && info.contains("attribute    c_ke in")
            && info.contains("attribute    z in [0, "),
        "{info}"
    );
    let alone = dir.path().join("z.mdlod");
    ok(&["convert", s(&dump), "-o", s(&alone), "--attribute", "z"]);
    let png = dir.path().join("p.png");
    let render = |file: &Path, extra: &[&str]| {
        let mut args = vec!["render", s(file), "-o", s(&png), "--colour-map", "viridis"];
        args.extend(["--width", "96", "--height", "64"]);
        args.extend(extra);
        let out = ok(&args);
        (out, read_png(&png).2)
    };
    let (_, by_ke) = render(&both, &[]);
    let (out, by_z) = render(&both, &["--attribute", "z"]);
    assert!(out.contains("colour map viridis: z from 0 to"), "{out}");
    let (_, z_alone) = render(&alone, &[]);
    assert_ne!(by_ke, by_z);
    // Particles' values are quantized alike; clusters' means may round apart.
    let worst = by_z
        .iter()
        .zip(&z_alone)
        .map(|(a, b)| a.abs_diff(*b))
        .max()
        .unwrap();
    assert!(worst <= 2, "{worst}");
    let e = fails(&[
        "render",
        s(&both),
        "-o",
        s(&png),
        "--colour-map",
        "viridis",
        "--attribute",
        "y",
    ]);
    assert!(
        e.contains("no attribute named \"y\" (the file keeps c_ke, z"),
        "{e}"
    );
    let e = fails(&["render", s(&both), "-o", s(&png), "--attribute", "z"]);
    assert!(
        e.contains("--attribute has no effect without --colour-map"),
        "{e}"
    );
    let e = fails(&[
        "convert",
        s(&dump),
        "-o",
        s(&both),
        "--attribute",
        "z",
        "--attribute",
        "z",
    ]);
    assert!(e.contains("--attribute z is given twice"), "{e}");
    // A batch: kept while the columns are the same, converted again when they change.
    let out = dir.path().join("d");
    let batch = |extra: &[&str]| {
        let mut args = vec!["batch", s(&dump), "-o", s(&out), "--attribute", "c_ke"];
        args.extend(extra);
        ok(&args)
    };
    batch(&["--attribute", "z"]);
    let info = ok(&["info", s(&out)]);
    assert!(info.contains("attribute    z in [0, "), "{info}");
    assert!(batch(&["--attribute", "z"]).contains("0 converted, 2 already done"));
    assert!(batch(&[]).contains("2 converted"));
    let m = mdlod_preprocess::batch::read_manifest(&out).unwrap();
    let f = MdlodFile::open(out.join(&m.frames[0].file)).unwrap();
    assert_eq!(f.attribute_names(), ["c_ke"]);
    // A GSD input's chunks keep their paths as names; the last part names them too.
    let gsd = Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/gsd/hoomd_mixture.gsd");
    let g = dir.path().join("g.mdlod");
    let mut args = vec!["convert", s(&gsd), "-o", s(&g)];
    args.extend(["--attribute", "charge", "--attribute", "mass"]);
    ok(&args);
    assert_eq!(
        MdlodFile::open(&g).unwrap().attribute_names(),
        ["particles/charge", "particles/mass"]
    );
    let out = ok(&[
        "render",
        s(&g),
        "-o",
        s(&png),
        "--width",
        "32",
        "--height",
        "24",
        "--colour-map",
        "viridis",
        "--attribute",
        "mass",
    ]);
    assert!(out.contains("colour map viridis: particles/mass"), "{out}");
}

/// A colour map over a file some of whose particles are hidden (a micelle's solvent,
/// whose value is 0) spans the values of the particles drawn by default, those a plane
/// cuts away left out too, in a still and in a movie, and its legend's ends are theirs;
/// `--attribute-range` still sets another.
#[test]
fn a_colour_map_spans_the_values_of_the_particles_shown() {
    let dir = tempfile::tempdir().unwrap();
    let mut frames = String::new();
    for t in 0..2 {
        let n = 2000;
        frames += &format!(
            "ITEM: TIMESTEP\n{t}\nITEM: NUMBER OF ATOMS\n{n}\nITEM: BOX BOUNDS pp pp pp\n0 20\n\
             0 20\n0 10\nITEM: ATOMS id type x y z c_rg\n"
        );
        for i in 0..n {
            // Type 1 from 1.5 to 3.6 (the frames apart), the solvent (type 3) at 0.
            let (ty, rg) = match i % 2 {
                0 => (
                    1,
                    1.5 + 2.1 * (i as f32 / n as f32) * (0.9 + 0.1 * t as f32),
                ),
                _ => (3, 0.0),
            };
            frames += &format!(
                "{} {ty} {} {} {} {rg}\n",
                i + 1,
                i % 20,
                (i / 20) % 20,
                i / 400
            );
        }
    }
    let dump = dir.path().join("mic.lammpstrj");
    std::fs::write(&dump, frames).unwrap();
    let file = dir.path().join("mic.mdlod");
    ok(&["convert", s(&dump), "-o", s(&file), "--attribute", "c_rg"]);
    let png = dir.path().join("m.png");
    let legend = dir.path().join("m.svg");
    let mut args = vec!["render", s(&file), "-o", s(&png), "--width", "96"];
    args.extend([
        "--height",
        "64",
        "--colour-map",
        "viridis",
        "--hide-species",
        "3",
    ]);
    args.extend(["--legend", s(&legend)]);
    let out = ok(&args);
    assert!(
        out.contains("c_rg from 1.5 to")
            && out.contains("the particles the map colours")
            && out.contains("the file's range is 0 to 3.59"),
        "{out}"
    );
    let svg = std::fs::read_to_string(&legend).unwrap();
    assert!(svg.contains(">1.5<") && !svg.contains(">0<"), "{svg}");
    // Cut by a plane too (z ≤ 1.5 keeps the first 800 atoms): the values left.
    let mut cut = args.clone();
    cut.extend(["--clip", "0,0,1,1.5"]);
    let out = ok(&cut);
    assert!(
        out.contains("c_rg from 1.5 to") && out.contains(" to 2.33"),
        "{out}"
    );
    // Given a range, it is the one drawn.
    let mut given = args.clone();
    given.extend(["--attribute-range", "0:4"]);
    let out = ok(&given);
    assert!(!out.contains("the particles the map colours"), "{out}");
    // A diverging map over a column of one sign (from 0 up) spreads the values drawn, as
    // the file's own range would, its white where their middle falls.
    let mut diverging = vec!["render", s(&file), "-o", s(&png), "--width", "96"];
    diverging.extend([
        "--height",
        "64",
        "--colour-map",
        "cool-warm",
        "--hide-species",
        "3",
    ]);
    let out = ok(&diverging);
    assert!(
        out.contains("c_rg from 1.5 to 3.5979 (over the values of the particles the map colours")
            && out.contains("the map's white at 2.54895"),
        "{out}"
    );
    // A movie: the frames' shown values.
    let d = dir.path().join("d");
    ok(&["batch", s(&dump), "-o", s(&d), "--attribute", "c_rg"]);
    let movie = dir.path().join("f-%d.png");
    let mut args = vec!["render", s(&d), "-o", s(&movie), "--width", "96"];
    args.extend([
        "--height",
        "64",
        "--colour-map",
        "viridis",
        "--hide-species",
        "3",
    ]);
    let out = ok(&args);
    assert!(out.contains("c_rg from 1.5 to"), "{out}");
    // A frame that draws nothing adds no values (frame 0's largest is 3.39).
    let mut args = vec!["render", s(&d), "-o", s(&movie), "--width", "96"];
    args.extend([
        "--height",
        "64",
        "--colour-map",
        "viridis",
        "--hide-attribute",
        ":3.5",
    ]);
    let out = ok(&args);
    assert!(
        out.contains("c_rg from 3.501") && out.contains("1 of the 2 frames draw nothing"),
        "{out}"
    );
}

/// `mdlod sample --colour-map` says what the colours mean as `mdlod render` does: the
/// attribute, its range and whose it is, and the scale.
#[test]
fn sample_names_its_colour_map_range_and_scale() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("c.lammpstrj");
    generate(&["crater", "-n", "3000"], &dump);
    let file = dir.path().join("c.mdlod");
    ok(&["convert", s(&dump), "-o", s(&file), "--attribute", "c_ke"]);
    let sndf = dir.path().join("c.sndf");
    let base = [
        "sample",
        s(&file),
        "-o",
        s(&sndf),
        "--width",
        "32",
        "--height",
        "24",
        "--iterations",
        "2",
        "--colour-map",
        "magma",
    ];
    let out = ok(&base);
    assert!(
        out.contains("colour map magma: c_ke from ") && out.contains("(the file's range)"),
        "{out}"
    );
    let out = ok(&[&base[..], &["--log-scale"]].concat());
    assert!(out.contains("(the file's range), on a log scale"), "{out}");
    let out = ok(&[&base[..], &["--attribute-range", "0.1:0.5"]].concat());
    assert!(
        out.contains("colour map magma: c_ke from 0.1 to 0.5 (--attribute-range)"),
        "{out}"
    );
    let out = ok(&[&base[..], &["--attribute-range=-1:-0.5", "--log-scale"]].concat());
    assert!(out.contains("--log-scale left unused"), "{out}");
}

/// `--axes`: a tripod of the data's axes in its corner, as the view sees them (looking
/// down z: x, red, to the right, y, green, up), in a still, a movie's frames and a
/// turntable's views (turning); refused where another panel takes its corner, and its
/// corner alone.
#[test]
fn axes_show_which_way_the_data_axes_point() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("c.lammpstrj");
    generate(&["crater", "-n", "3000", "--frames", "2"], &dump);
    let file = dir.path().join("c.mdlod");
    ok(&["convert", s(&dump), "-o", s(&file)]);
    // The mean place of the pixels of a colour in the bottom-right panel (84 × 84 inside
    // a margin of 8; data under it is drawn pale).
    let mean_of = |png: &Path, want: fn(&[u8]) -> bool| {
        let (w, h, px) = read_png(png);
        let (mut sx, mut sy, mut n) = (0f64, 0f64, 0f64);
        for y in h - 92..h - 8 {
            for x in w - 92..w - 8 {
                let i = 4 * (y * w + x) as usize;
                if want(&px[i..i + 3]) {
                    sx += f64::from(x);
                    sy += f64::from(y);
                    n += 1.0;
                }
            }
        }
        assert!(n >= 20.0, "{}: {n} pixels of the colour", png.display());
        (sx / n, sy / n)
    };
    let red = |p: &[u8]| p[0] > 150 && p[1] < 110 && p[2] < 110;
    let green = |p: &[u8]| p[1] > 120 && p[0] < 110 && p[2] < 110;
    let check = |png: &Path| {
        let (rx, ry) = mean_of(png, red);
        let (gx, gy) = mean_of(png, green);
        // x to the right of y's line, y above x's.
        assert!(
            rx > gx + 8.0,
            "{}: red at {rx:.1}, green at {gx:.1}",
            png.display()
        );
        assert!(
            gy < ry - 8.0,
            "{}: green at {gy:.1}, red at {ry:.1}",
            png.display()
        );
    };
    let png = dir.path().join("a.png");
    let mut args = vec!["render", s(&file), "-o", s(&png), "--axes"];
    args.extend(["--width", "320", "--height", "200", "--background", "white"]);
    args.extend(["--look-along", "0,0,-1"]);
    ok(&args);
    check(&png);
    let d = dir.path().join("d");
    ok(&["batch", s(&dump), "-o", s(&d)]);
    let movie = dir.path().join("m-%d.png");
    let mut args = vec!["render", s(&d), "-o", s(&movie), "--axes"];
    args.extend(["--width", "320", "--height", "200", "--background", "white"]);
    args.extend(["--look-along", "0,0,-1"]);
    ok(&args);
    for k in 0..2 {
        check(&dir.path().join(format!("m-{k}.png")));
    }
    // A turntable: each view its own tripod, turning with the data (from azimuth 0 along
    // x, y on one side of the upright z, on the other half a turn on).
    let spin = dir.path().join("t-%d.png");
    let mut args = vec![
        "render",
        s(&file),
        "-o",
        s(&spin),
        "--axes",
        "--turntable",
        "2",
    ];
    args.extend(["--width", "320", "--height", "200", "--background", "white"]);
    args.extend(["--azimuth", "0", "--elevation", "0"]);
    ok(&args);
    let x_of = |k: usize| {
        let png = dir.path().join(format!("t-{k}.png"));
        let blue = |p: &[u8]| p[2] > 140 && p[0] < 110 && p[1] < 150;
        (mean_of(&png, green).0, mean_of(&png, blue).0)
    };
    let ((r0, c0), (r1, c1)) = (x_of(0), x_of(1));
    assert!(
        (r0 - c0).abs() > 8.0 && (r1 - c1).abs() > 8.0 && (r0 - c0).signum() != (r1 - c1).signum(),
        "y at {r0:.1} then {r1:.1}, z at {c0:.1} then {c1:.1}"
    );
    assert!(
        r0 > c0 + 8.0 && r1 < c1 - 8.0,
        "y at {r0:.1} then {r1:.1}, z at {c0:.1} then {c1:.1}"
    );
    // Its corner taken by the legend, it takes the next free one (bottom-left).
    let mut args = vec!["render", s(&file), "-o", s(&png), "--axes"];
    args.extend(["--width", "320", "--height", "200", "--background", "white"]);
    args.extend(["--look-along", "0,0,-1", "--legend-in-image"]);
    ok(&args);
    let (w, h, px) = read_png(&png);
    let red_in_panel = (h - 92..h - 8)
        .flat_map(|y| (8..92u32).map(move |x| (x, y)))
        .filter(|&(x, y)| {
            let i = 4 * (y * w + x) as usize;
            px[i] > 150 && px[i + 1] < 110 && px[i + 2] < 110
        })
        .count();
    assert!(
        red_in_panel >= 20,
        "{red_in_panel} red pixels in the bottom-left panel"
    );
    // An image too small for them: refused before anything is drawn, at the scale given.
    for (size, scale, says) in [
        (
            "90",
            None,
            "a 90×90 image cannot hold the axes (at least 100×100",
        ),
        (
            "150",
            Some("2"),
            "at --text-scale 2): draw a larger image, or a smaller --text-scale",
        ),
    ] {
        let out = dir.path().join("small.png");
        let mut args = vec!["render", s(&file), "-o", s(&out), "--axes"];
        args.extend(["--width", size, "--height", size]);
        if let Some(k) = scale {
            args.extend(["--text-scale", k]);
        }
        let e = fails(&args);
        assert!(e.contains(says), "{e}");
        assert!(!out.exists(), "drawn before refused");
    }
    for (extra, says) in [
        (
            &["--axes-corner", "top-right"][..],
            "--axes-corner has no effect without --axes",
        ),
        (
            &[
                "--axes",
                "--axes-corner",
                "bottom-right",
                "--ortho",
                "--scale-bar",
                "--scale-bar-corner",
                "bottom-right",
            ][..],
            "--axes and --scale-bar both draw at the bottom-right corner",
        ),
    ] {
        let out = dir.path().join("no.png");
        let mut args = vec!["render", s(&file), "-o", s(&out), "--width", "320"];
        args.extend(["--height", "200"]);
        args.extend(extra);
        let e = fails(&args);
        assert!(e.contains(says), "{extra:?}: {e}");
        assert!(!out.exists(), "{extra:?}: drawn before refused");
    }
}

/// `--scale-bar`: a bar of the length given (or a round one) as long in pixels as that
/// length of the world in an orthographic view, in a still and in every frame of a
/// movie; refused in perspective and where another panel takes its corner.
#[test]
fn a_scale_bar_is_as_long_as_its_length_of_the_world() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("c.lammpstrj");
    generate(&["crater", "-n", "3000", "--frames", "2"], &dump);
    let file = dir.path().join("c.mdlod");
    ok(&["convert", s(&dump), "-o", s(&file)]);
    let png = dir.path().join("s.png");
    let view = dir.path().join("v.json");
    // The longest run of black pixels in a row of the image's bottom band.
    let longest_black = |png: &Path| {
        let (w, h, px) = read_png(png);
        (h - 40..h)
            .map(|y| {
                let (mut best, mut run) = (0u32, 0u32);
                for x in 0..w {
                    let i = 4 * (y * w + x) as usize;
                    if px[i..i + 3] == [0, 0, 0] {
                        run += 1;
                        best = best.max(run);
                    } else {
                        run = 0;
                    }
                }
                best
            })
            .max()
            .unwrap()
    };
    let per_px = |view: &Path, height: f64| {
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(view).unwrap()).unwrap();
        let d = v["distance"].as_f64().unwrap();
        let fov = v["fov_y_deg"].as_f64().unwrap().to_radians();
        let zoom = v["zoom"].as_f64().unwrap();
        2.0 * d * (fov / 2.0).tan() / zoom / height
    };
    let mut args = vec!["render", s(&file), "-o", s(&png), "--ortho", "--scale-bar"];
    args.extend(["--width", "320", "--height", "200", "--background", "white"]);
    args.extend(["--scale-bar-length", "20", "--save-view", s(&view)]);
    ok(&args);
    let want = 20.0 / per_px(&view, 200.0);
    let got = f64::from(longest_black(&png));
    assert!((got - want).abs() <= 1.5, "{got} px against {want:.1}");
    // A movie: every frame its bar.
    let d = dir.path().join("d");
    ok(&["batch", s(&dump), "-o", s(&d)]);
    let movie = dir.path().join("m-%d.png");
    let mut args = vec!["render", s(&d), "-o", s(&movie), "--ortho", "--scale-bar"];
    args.extend(["--width", "320", "--height", "200", "--background", "white"]);
    args.extend(["--scale-bar-length", "20", "--save-view", s(&view)]);
    ok(&args);
    let want = 20.0 / per_px(&view, 200.0);
    for k in 0..2 {
        let got = f64::from(longest_black(&dir.path().join(format!("m-{k}.png"))));
        assert!(
            (got - want).abs() <= 1.5,
            "frame {k}: {got} px against {want:.1}"
        );
    }
    // A turntable: one distance, so one bar in every view; a perspective one is refused
    // before any view is drawn.
    let spin = dir.path().join("spin-%d.png");
    let mut args = vec!["render", s(&file), "-o", s(&spin), "--ortho", "--scale-bar"];
    args.extend(["--width", "320", "--height", "200", "--background", "white"]);
    args.extend(["--scale-bar-length", "20", "--turntable", "3"]);
    args.extend(["--save-view", s(&view)]);
    ok(&args);
    let want = 20.0 / per_px(&view, 200.0);
    for k in 0..3 {
        let got = f64::from(longest_black(&dir.path().join(format!("spin-{k}.png"))));
        assert!(
            (got - want).abs() <= 1.5,
            "view {k}: {got} px against {want:.1}"
        );
    }
    let flat = dir.path().join("flat-%d.png");
    let e = fails(&[
        "render",
        s(&file),
        "-o",
        s(&flat),
        "--scale-bar",
        "--turntable",
        "3",
    ]);
    assert!(e.contains("needs an orthographic view"), "{e}");
    assert!(!dir.path().join("flat-0.png").exists());
    for (extra, says) in [
        (&["--scale-bar"][..], "needs an orthographic view"),
        (
            &["--ortho", "--scale-bar-length", "5"][..],
            "no effect without --scale-bar",
        ),
        (
            &["--ortho", "--scale-bar-corner", "top-right"][..],
            "--scale-bar-corner has no effect without --scale-bar",
        ),
        (
            &[
                "--ortho",
                "--scale-bar",
                "--label",
                "x",
                "--label-corner",
                "bottom-left",
            ][..],
            "--scale-bar and --label both draw at the bottom-left corner",
        ),
        (
            &["--ortho", "--scale-bar", "--scale-bar-length", "1e6"][..],
            "too long for a 320-pixel image",
        ),
    ] {
        let out = dir.path().join("no.png");
        let mut args = vec!["render", s(&file), "-o", s(&out), "--width", "320"];
        args.extend(["--height", "200"]);
        args.extend(extra);
        let e = fails(&args);
        assert!(e.contains(says), "{extra:?}: {e}");
        assert!(!out.exists(), "{extra:?}: drawn before refused");
    }
}

/// `--save-map` writes the splats' light as floats: for a uniform slab of particles of
/// mass 1 lit by m/(π r²), the column density (4 per unit area in its middle) and in
/// all the mass (the map's sum times a pixel's world area), read from the .npy as
/// NumPy would; refused where the pixels hold no amounts.
#[test]
fn a_saved_light_map_holds_the_column_density() {
    let dir = tempfile::tempdir().unwrap();
    // 40 × 40 columns, four particles deep, one unit apart, radius 0.5.
    let r = 0.5f64;
    let sigma = 1.0 / (std::f64::consts::PI * r * r);
    let mut xyz = String::new();
    xyz.push_str("6400\n");
    xyz.push_str(
        "Lattice=\"40 0 0 0 40 0 0 0 4\" Properties=species:S:1:pos:R:3:radius:R:1:sigma:R:1\n",
    );
    for k in 0..4 {
        for j in 0..40 {
            for i in 0..40 {
                xyz.push_str(&format!("A {}.5 {}.5 {}.5 {r} {sigma}\n", i, j, k));
            }
        }
    }
    let input = dir.path().join("slab.xyz");
    std::fs::write(&input, xyz).unwrap();
    let file = dir.path().join("slab.mdlod");
    ok(&["convert", s(&input), "-o", s(&file), "--attribute", "sigma"]);
    let (png, map, view) = (
        dir.path().join("m.png"),
        dir.path().join("m.npy"),
        dir.path().join("v.json"),
    );
    let (w, h) = (200usize, 180usize);
    let (ws, hs) = (w.to_string(), h.to_string());
    let mut args = vec!["render", s(&file), "-o", s(&png), "--mode", "splat"];
    args.extend([
        "--intensity",
        "attribute",
        "--ortho",
        "--look-along",
        "0,0,-1",
    ]);
    args.extend(["--kernel-scale", "4", "--screen-error", "0", "--width", &ws]);
    args.extend([
        "--height",
        &hs,
        "--save-map",
        s(&map),
        "--save-view",
        s(&view),
    ]);
    let out = ok(&args);
    assert!(out.contains("light map (200×180 floats) saved to"), "{out}");
    let bytes = std::fs::read(&map).unwrap();
    assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00");
    let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    assert_eq!((10 + header_len) % 64, 0);
    let header = std::str::from_utf8(&bytes[10..10 + header_len]).unwrap();
    assert!(
        header.contains("'descr': '<f4'") && header.contains("'shape': (180, 200)"),
        "{header}"
    );
    let values: Vec<f32> = bytes[10 + header_len..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    assert_eq!(values.len(), w * h);
    // The middle: 4 per unit area (the kernels of a lattice overlap smoothly).
    let middle: Vec<f32> = (h / 2 - 5..h / 2 + 5)
        .flat_map(|y| (w / 2 - 5..w / 2 + 5).map(move |x| (x, y)))
        .map(|(x, y)| values[y * w + x])
        .collect();
    for v in &middle {
        assert!((v - 4.0).abs() < 0.04, "column density {v} against 4");
    }
    // Everything: the map's sum times a pixel's area is the slab's mass, 6400.
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&view).unwrap()).unwrap();
    let (d, fov, zoom) = (
        v["distance"].as_f64().unwrap(),
        v["fov_y_deg"].as_f64().unwrap().to_radians(),
        v["zoom"].as_f64().unwrap(),
    );
    let per_px = 2.0 * d * (fov / 2.0).tan() / zoom / h as f64;
    let mass: f64 = values.iter().map(|&v| f64::from(v)).sum::<f64>() * per_px * per_px;
    assert!(
        (mass / 6400.0 - 1.0).abs() < 2e-3,
        "mass {mass} against 6400"
    );
    // Refused: a mode whose pixels are colours, a movie's name, another extension.
    for (extra, says) in [
        (vec!["--save-map", s(&map)], "give --mode splat"),
        (
            vec!["--mode", "splat", "--save-map", "m.png"],
            "the map is a NumPy array: name it .npy",
        ),
    ] {
        let mut args = vec!["render", s(&file), "-o", s(&png)];
        args.extend(extra);
        let o = mdlod(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains(says), "{err}");
    }
}

/// Panels drawn into an image are refused before anything is drawn where they would
/// cover one another (a long scale bar reaching under the legend, in a still or a
/// movie) or where the image cannot hold the scale bar at all: no image is left.
#[test]
fn panels_that_would_cover_one_another_are_refused_before_drawing() {
    let dir = tempfile::tempdir().unwrap();
    let input = lammps_sample_path("cu_melt.custom.dump");
    let file = dir.path().join("m.mdlod");
    ok(&["convert", s(&input), "-o", s(&file), "--attribute", "c_pe"]);
    let png = dir.path().join("p.png");
    let base = [
        "--ortho",
        "--scale-bar",
        "--legend-in-image",
        "--colour-map",
        "viridis",
    ];
    // A bar of 30 Å in 800 pixels reaches under the legend.
    let long_bar = [
        "--width",
        "800",
        "--height",
        "600",
        "--scale-bar-length",
        "30",
    ];
    let e = fails(&[&["render", s(&file), "-o", s(&png)][..], &base, &long_bar].concat());
    assert!(
        e.contains("--legend-in-image and --scale-bar would cover one another in a 800×600 image")
            && e.contains("a shorter bar (--scale-bar-length)"),
        "{e}"
    );
    assert!(!png.exists());
    // The bar's own length, short enough: drawn, beside the legend.
    let out = ok(&[
        &["render", s(&file), "-o", s(&png)][..],
        &base,
        &[
            "--width",
            "800",
            "--height",
            "600",
            "--scale-bar-length",
            "5",
        ],
    ]
    .concat());
    assert!(out.contains("legend drawn into"), "{out}");
    // The label in a corner the legend spans: the legend and the label at the bottom.
    std::fs::remove_file(&png).unwrap();
    let e = fails(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--width",
        "420",
        "--height",
        "300",
        "--legend-in-image",
        "--colour-map",
        "viridis",
        "--label",
        "a rather long label of the frame, timestep {timestep}",
        "--label-corner",
        "bottom-left",
    ]);
    assert!(
        e.contains("--legend-in-image and --label would cover one another"),
        "{e}"
    );
    assert!(!png.exists());
    // An image too small for the bar: refused before the image is written.
    let e = fails(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--ortho",
        "--scale-bar",
        "--width",
        "40",
        "--height",
        "30",
    ]);
    assert!(e.contains("a 40×30 image cannot hold the scale bar"), "{e}");
    assert!(!png.exists());
    // A movie: refused before its first frame.
    let d = dir.path().join("m.d");
    ok(&["batch", s(&input), "-o", s(&d), "--attribute", "c_pe"]);
    let frames = dir.path().join("f-%d.png");
    let e = fails(&[&["render", s(&d), "-o", s(&frames)][..], &base, &long_bar].concat());
    assert!(e.contains("would cover one another"), "{e}");
    assert!(!dir.path().join("f-0.png").exists());
}

/// `--text-scale N` draws the in-image panels N times their size (print figures whose
/// default panels read small), and the fit keeps the larger panel's room; a scale the
/// image cannot hold is refused before drawing.
#[test]
fn text_scale_enlarges_the_panels_drawn_into_an_image() {
    let dir = tempfile::tempdir().unwrap();
    let input = lammps_sample_path("cu_melt.custom.dump");
    let file = dir.path().join("m.mdlod");
    ok(&["convert", s(&input), "-o", s(&file), "--attribute", "c_pe"]);
    let base = [
        "--width",
        "800",
        "--height",
        "600",
        "--background",
        "#000000",
    ];
    let panel_box = |png: &Path| {
        // The panel is 85 % white over black: the box of the bright pixels at the bottom
        // right, where the fit leaves no particle.
        let (w, h, px) = read_png(png);
        let (mut x0, mut y0) = (w, h);
        for y in h / 2..h {
            for x in 0..w {
                let i = 4 * (y * w + x) as usize;
                if px[i..i + 3].iter().all(|&c| c > 200) {
                    (x0, y0) = (x0.min(x), y0.min(y));
                }
            }
        }
        (w - x0, h - y0)
    };
    let one = dir.path().join("one.png");
    let out = ok(&[
        &["render", s(&file), "-o", s(&one)][..],
        &base,
        &["--colour-map", "viridis", "--legend-in-image"],
    ]
    .concat());
    assert!(!out.contains("covers drawn particles"), "{out}");
    let three = dir.path().join("three.png");
    let out = ok(&[
        &["render", s(&file), "-o", s(&three)][..],
        &base,
        &[
            "--colour-map",
            "viridis",
            "--legend-in-image",
            "--text-scale",
            "2",
        ],
    ]
    .concat());
    assert!(!out.contains("covers drawn particles"), "{out}");
    let ((w1, h1), (w2, h2)) = (panel_box(&one), panel_box(&three));
    // Each with its margin of 8 pixels times the scale.
    assert_eq!(
        (w2 - 16, h2 - 16),
        (2 * (w1 - 8), 2 * (h1 - 8)),
        "{w1}×{h1} against {w2}×{h2}"
    );
    let e = fails(
        &[
            &["render", s(&file), "-o", s(&three)][..],
            &base,
            &[
                "--colour-map",
                "viridis",
                "--legend-in-image",
                "--text-scale",
                "3",
            ],
        ]
        .concat(),
    );
    assert!(e.contains("cannot hold the legend (at least"), "{e}");
    let e = fails(&["render", s(&file), "-o", s(&three), "--text-scale", "9"]);
    assert!(e.contains("--text-scale"), "{e}");
}

/// `--scale-bar-unit` names the bar's unit where the file records none (generated data,
/// dumps without `units`): the bar's label changes and nothing else; it needs a bar and
/// a unit the image's font draws.
#[test]
fn a_scale_bar_takes_the_unit_it_is_given() {
    let dir = tempfile::tempdir().unwrap();
    let input = lammps_sample_path("cu_melt.custom.dump");
    let file = dir.path().join("m.mdlod");
    ok(&["convert", s(&input), "-o", s(&file)]);
    let (plain, named) = (dir.path().join("plain.png"), dir.path().join("named.png"));
    let view = dir.path().join("v.json");
    let base = [
        "--ortho",
        "--scale-bar",
        "--width",
        "400",
        "--height",
        "300",
    ];
    ok(&[
        &["render", s(&file), "-o", s(&plain), "--save-view", s(&view)][..],
        &base,
    ]
    .concat());
    ok(&[
        &["render", s(&file), "-o", s(&named), "--view", s(&view)][..],
        &base,
        &["--scale-bar-unit", "nm"],
    ]
    .concat());
    let ((w, h, a), (_, _, b)) = (read_png(&plain), read_png(&named));
    let changed: Vec<(u32, u32)> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .filter(|&(x, y)| {
            let i = 4 * (y * w + x) as usize;
            a[i..i + 4] != b[i..i + 4]
        })
        .collect();
    assert!(!changed.is_empty());
    // Only the label, in the bottom-left panel.
    assert!(
        changed.iter().all(|&(x, y)| x < w / 2 && y > h - 60),
        "{:?}",
        changed[0]
    );
    let e = fails(&[
        "render",
        s(&file),
        "-o",
        s(&named),
        "--scale-bar-unit",
        "nm",
    ]);
    assert!(e.contains("give --scale-bar"), "{e}");
    let e = fails(
        &[
            &["render", s(&file), "-o", s(&named)][..],
            &base,
            &["--scale-bar-unit", "日"],
        ]
        .concat(),
    );
    assert!(
        e.contains("a unit of at most 12 characters the image's font"),
        "{e}"
    );
}

/// A fitted view leaves the scale bar's panel free, as it does the legend's: a slab
/// filling the image reaches under the panel's corner without the bar and stays clear
/// of it with the bar (the view the bar's fit chose, drawn without the bar, has only
/// background there).
#[test]
fn a_fitted_view_keeps_the_data_from_under_the_scale_bar() {
    let dir = tempfile::tempdir().unwrap();
    let mut xyz = String::from("2560\nProperties=species:S:1:pos:R:3\n");
    for j in 0..40 {
        for i in 0..64 {
            xyz.push_str(&format!("A {i} {j} 0\n"));
        }
    }
    let input = dir.path().join("sheet.xyz");
    std::fs::write(&input, xyz).unwrap();
    let file = dir.path().join("sheet.mdlod");
    ok(&["convert", s(&input), "-o", s(&file), "--radius", "A=0.5"]);
    let (w, h) = (320usize, 200usize);
    let base = [
        "--width",
        "320",
        "--height",
        "200",
        "--background",
        "white",
        "--ortho",
        "--look-along",
        "0,0,-1",
    ];
    // Data pixels in the panel's corner (bottom left: a fifth of the width, 30 rows).
    let covered = |png: &Path| {
        let (_, _, px) = read_png(png);
        (h - 30..h)
            .flat_map(|y| (0..w / 5).map(move |x| (x, y)))
            .filter(|&(x, y)| px[4 * (y * w + x)..4 * (y * w + x) + 3] != [255, 255, 255])
            .count()
    };
    let plain = dir.path().join("plain.png");
    let mut args = vec!["render", s(&file), "-o", s(&plain)];
    args.extend(base);
    ok(&args);
    assert!(covered(&plain) > 100, "{}", covered(&plain));
    let (barred, view) = (dir.path().join("bar.png"), dir.path().join("v.json"));
    let mut args = vec!["render", s(&file), "-o", s(&barred), "--scale-bar"];
    args.extend(base);
    args.extend(["--save-view", s(&view)]);
    ok(&args);
    let clear = dir.path().join("clear.png");
    let mut args = vec!["render", s(&file), "-o", s(&clear), "--view", s(&view)];
    args.extend(["--width", "320", "--height", "200", "--background", "white"]);
    ok(&args);
    assert_eq!(covered(&clear), 0);
}

/// `--hide-by` reads `--hide-attribute` against another attribute than the colour's
/// (OVITO's select by structure type, delete, colour by energy): of the real bicrystal's
/// 2552 atoms the 2047 its CNA calls fcc (1) are left out, every other one drawn, in the
/// energy's colours; the option alone, or naming no attribute of the file, is refused.
#[test]
fn hidden_values_can_be_read_from_another_attribute_than_the_colours() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("gb.mdlod");
    let dump = lammps_sample_path("cu_gb.cna.dump");
    ok(&[
        "convert",
        s(&dump),
        "-o",
        s(&file),
        "--attribute",
        "c_cna",
        "--attribute",
        "c_pe",
    ]);
    let png = |name: &str| dir.path().join(name);
    let (pe_png, cna_png, x_png) = (png("pe.png"), png("cna.png"), png("x.png"));
    let drawn = |out: &str| -> u64 {
        let at = out.find(" particles").unwrap();
        out[..at].rsplit(' ').next().unwrap().parse().unwrap()
    };
    let base = [
        "--width",
        "96",
        "--height",
        "64",
        "--screen-error",
        "0",
        "--no-occlusion",
    ];
    let mut args = vec!["render", s(&file), "-o", s(&pe_png)];
    args.extend(base);
    args.extend(["--attribute", "c_pe", "--colour-map", "viridis"]);
    args.extend(["--hide-by", "c_cna", "--hide-attribute", "0.5:1.5"]);
    let out = ok(&args);
    assert_eq!(drawn(&out), 2552 - 2047, "{out}");
    // The same atoms as hiding by the colour attribute itself, in other colours.
    let mut args = vec!["render", s(&file), "-o", s(&cna_png)];
    args.extend(base);
    args.extend(["--attribute", "c_cna", "--colour-map", "viridis"]);
    args.extend(["--hide-attribute", "0.5:1.5"]);
    let out = ok(&args);
    assert_eq!(drawn(&out), 2552 - 2047, "{out}");
    assert_ne!(read_png(&pe_png).2, read_png(&cna_png).2);
    for (extra, says) in [
        (
            vec!["--hide-by", "c_cna"],
            "--hide-by has no effect without --hide-attribute",
        ),
        (
            vec!["--hide-by", "c_ke", "--hide-attribute", "0.5:1.5"],
            "c_ke",
        ),
    ] {
        let mut args = vec!["render", s(&file), "-o", s(&x_png)];
        args.extend(extra);
        let o = mdlod(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains(says), "{err}");
        if says == "c_ke" {
            assert!(err.contains("c_cna, c_pe"), "{err}");
        }
    }
}

/// Under a colour map, species given colours of their own take no part of the map's
/// range: a granular run's large grains drawn grey leave the map to the small grains'
/// radii, whose colours would otherwise share a third of it.
#[test]
fn species_in_colours_of_their_own_leave_the_map_its_range() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("g.mdlod");
    ok(&[
        "convert",
        s(&lammps_sample_path("granular.dump")),
        "-o",
        s(&file),
        "--attribute",
        "radius",
    ]);
    let png = dir.path().join("g.png");
    let range = |extra: &[&str]| -> [f64; 2] {
        let mut args = vec![
            "render",
            s(&file),
            "-o",
            s(&png),
            "--width",
            "48",
            "--height",
            "32",
            "--colour-map",
            "viridis",
            "--json",
        ];
        args.extend_from_slice(extra);
        let o = mdlod(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let r = v["attribute_range"].as_array().cloned().unwrap_or_default();
        match r.as_slice() {
            [lo, hi] => [lo.as_f64().unwrap(), hi.as_f64().unwrap()],
            _ => panic!("{v}"),
        }
    };
    // The file's radii, then the small grains' (type 1) alone: the large ones' (type
    // 2) are grey.
    let all = range(&[]);
    let small = range(&["--species-colour", "2=grey"]);
    assert!(all[1] > 0.8, "{all:?}");
    assert!(
        (small[0] - all[0]).abs() < 1e-4 && small[1] < 0.6,
        "{small:?} against {all:?}"
    );
    // Hiding the large grains gives the same range.
    assert_eq!(range(&["--hide-species", "2"]), small);
}

/// `--json` leaves one line of JSON per result on standard output and the text on
/// standard error: convert, verify (a file and a batch directory), batch, a still (its
/// notes in it) and a turntable (a line per image), each parsed and checked against what
/// was done.
#[test]
fn json_output_gives_one_object_per_result() {
    let dir = tempfile::tempdir().unwrap();
    let dump = lammps_sample_path("cu_gb.cna.dump");
    let file = dir.path().join("gb.mdlod");
    let json = |args: &[&str]| -> Vec<serde_json::Value> {
        let o = mdlod(args);
        assert!(
            o.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        String::from_utf8(o.stdout)
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{l}: {e}")))
            .collect()
    };
    let c = json(&[
        "convert",
        s(&dump),
        "-o",
        s(&file),
        "--attribute",
        "c_pe",
        "--json",
    ]);
    assert_eq!(c.len(), 1);
    assert_eq!(c[0]["particles"], 2552);
    // The frame's timestep (as the dump gives it), beside its index.
    let step: u64 = std::fs::read_to_string(&dump)
        .unwrap()
        .lines()
        .nth(1)
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    assert_eq!(c[0]["timestep"].as_u64(), Some(step), "{}", c[0]);
    assert_eq!(c[0]["output"], s(&file));
    assert_eq!(
        c[0]["bytes"].as_u64(),
        Some(std::fs::metadata(&file).unwrap().len())
    );
    let v = json(&["verify", s(&file), "--json"]);
    assert_eq!(
        (v[0]["ok"].as_bool(), v[0]["points_decoded"].as_u64()),
        (Some(true), Some(2552))
    );
    let png = dir.path().join("a.png");
    let r = json(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--width",
        "64",
        "--height",
        "48",
        "--hide-attribute",
        "5:6",
        "--json",
    ]);
    assert_eq!(r.len(), 1);
    assert_eq!(
        (r[0]["width"].as_u64(), r[0]["height"].as_u64()),
        (Some(64), Some(48))
    );
    assert!(r[0]["particles_drawn"].as_u64().unwrap() > 0);
    assert_eq!(r[0]["camera"]["azimuth_deg"].as_f64(), Some(30.0));
    let notes = r[0]["notes"].as_array().unwrap();
    assert!(
        notes
            .iter()
            .any(|n| n.as_str().unwrap().contains("hides no particle")),
        "{notes:?}"
    );
    let spin = dir.path().join("spin-%d.png");
    let t = json(&[
        "render",
        s(&file),
        "-o",
        s(&spin),
        "--width",
        "32",
        "--height",
        "24",
        "--turntable",
        "3",
        "--json",
    ]);
    // A line per view, and one for the turn with the notes said after its images.
    assert_eq!(t.len(), 4);
    assert_eq!(t[2]["output"], s(&dir.path().join("spin-2.png")));
    assert_eq!(
        (t[2]["view"].as_u64(), t[2]["views"].as_u64()),
        (Some(2), Some(3))
    );
    assert_eq!(t[3]["series"], s(&spin));
    let b = dir.path().join("b.d");
    let j = json(&[
        "batch",
        s(&dump),
        "-o",
        s(&b),
        "--attribute",
        "c_pe",
        "--json",
    ]);
    assert_eq!(
        (j[0]["frames"].as_u64(), j[0]["converted"].as_u64()),
        (Some(1), Some(1))
    );
    let j = json(&[
        "batch",
        s(&dump),
        "-o",
        s(&b),
        "--attribute",
        "c_pe",
        "--json",
    ]);
    assert_eq!(
        (j[0]["already_done"].as_u64(), j[0]["to_convert"].as_u64()),
        (Some(1), Some(0))
    );
    let v = json(&["verify", s(&b), "--json"]);
    assert_eq!(
        (v[0]["ok"].as_bool(), v[0]["frames_ok"].as_u64()),
        (Some(true), Some(1))
    );
    // A movie: each frame's line names its frame, timestep and file, and the colours'
    // attribute and range.
    let movie = dir.path().join("m-%d.png");
    let m = json(&[
        "render",
        s(&b),
        "-o",
        s(&movie),
        "--width",
        "96",
        "--height",
        "64",
        "--colour-map",
        "viridis",
        "--dt",
        "0.002",
        "--label",
        "{time}",
        "--json",
    ]);
    assert_eq!(m.len(), 2);
    // A key drawn into the image is named (a script can tell the PNG has one).
    let keyed = json(&[
        "render",
        s(&file),
        "-o",
        s(&dir.path().join("k.png")),
        "--width",
        "480",
        "--height",
        "200",
        "--legend-in-image=bottom-right",
        "--json",
    ]);
    assert_eq!(
        (
            keyed[0]["legend_in_image"].as_str(),
            keyed[0]["legend"].as_str()
        ),
        (Some("bottom-right"), None)
    );
    assert_eq!(m[0]["legend_in_image"], serde_json::Value::Null);
    // Splats give the exposure they chose (which the pieces of a movie must share) and
    // their light.
    let splat = json(&[
        "render",
        s(&file),
        "-o",
        s(&dir.path().join("s.png")),
        "--width",
        "48",
        "--height",
        "32",
        "--mode",
        "splat",
        "--json",
    ]);
    assert!(
        splat[0]["exposure"].as_f64().is_some_and(|e| e > 0.0)
            && splat[0]["total_flux"].as_f64().is_some_and(|f| f > 0.0),
        "{}",
        splat[0]
    );
    // (`--dt` gives each frame's time, as the label's.)
    assert!(
        (m[0]["time"].as_f64().unwrap() - 0.2).abs() < 1e-9,
        "{}",
        m[0]
    );
    assert_eq!(
        (m[0]["frame"].as_u64(), m[0]["timestep"].as_u64()),
        (Some(0), Some(100))
    );
    assert!(m[0]["frame_file"]
        .as_str()
        .unwrap()
        .ends_with("frame-100.mdlod"));
    assert_eq!(m[0]["attribute"], "c_pe");
    assert_eq!(m[0]["attribute_range"].as_array().map(Vec::len), Some(2));
    assert_eq!(m[0]["pool_limited"].as_bool(), Some(false));
    // A movie whose second frame is damaged: the first image's line, then the
    // failure's, `ok` false with the error (a script reading standard output used to see
    // one image and no failure).
    let melt = dir.path().join("melt.d");
    let dump6 = lammps_sample_path("cu_melt.custom.dump");
    json(&["batch", s(&dump6), "-o", s(&melt), "--json"]);
    let listed = mdlod_preprocess::batch::read_manifest(&melt).unwrap();
    let second = melt.join(&listed.frames[1].file);
    let kept = std::fs::read(&second).unwrap();
    let mut flipped = kept.clone();
    let at = flipped.len() / 2;
    flipped[at] ^= 0xff;
    std::fs::write(&second, &flipped).unwrap();
    let o = mdlod(&[
        "render",
        s(&melt),
        "-o",
        s(&movie),
        "--frames",
        "0:2",
        "--width",
        "48",
        "--height",
        "32",
        "--json",
    ]);
    let lines: Vec<serde_json::Value> = String::from_utf8(o.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert!(!o.status.success());
    assert_eq!(lines.len(), 2, "{lines:?}");
    assert_eq!(
        (lines[0]["ok"].as_bool(), lines[1]["ok"].as_bool()),
        (Some(true), Some(false))
    );
    assert!(lines[1]["error"].as_str().is_some_and(|e| !e.is_empty()));
    std::fs::write(&second, kept).unwrap();
    // An option the mode does not read, refused before rendering: its object too.
    let o = mdlod(&[
        "render",
        s(&file),
        "-o",
        s(&dir.path().join("o.png")),
        "--iterations",
        "4",
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(
        v["ok"] == false && v["error"].as_str().unwrap().contains("--iterations"),
        "{v}"
    );
    // A command line that does not parse: its object too, with clap's status (2).
    let o = mdlod(&[
        "render",
        s(&file),
        "-o",
        s(&dir.path().join("o.png")),
        "--clip",
        "0,0,0,1",
        "--json",
    ]);
    assert_eq!(o.status.code(), Some(2));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(
        v["ok"] == false && v["error"].as_str().unwrap().contains("--clip"),
        "{v}"
    );
    let o = mdlod(&["verify", s(&file), "--json", "--no-such-option"]);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(
        v["ok"] == false && v["error"].as_str().unwrap().contains("--no-such-option"),
        "{v}"
    );
    // A missing argument is named in the object, as the lines under clap's first say.
    for (args, named) in [
        (&["verify", "--json"][..], "<FILE>"),
        (&["batch", s(&file), "--json"], "--output"),
    ] {
        let o = mdlod(args);
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let e = v["error"].as_str().unwrap();
        assert!(
            e.starts_with("the following required arguments were not provided:")
                && e.contains(named)
                && !e.contains("Usage"),
            "{v}"
        );
    }
    // A damaged file: `ok` false with the error, and the failure's status.
    let bad = dir.path().join("bad.mdlod");
    let mut bytes = std::fs::read(&file).unwrap();
    let at = bytes.len() / 2;
    bytes[at] ^= 0xff;
    std::fs::write(&bad, bytes).unwrap();
    let o = mdlod(&["verify", s(&bad), "--json"]);
    assert_eq!(o.status.code(), Some(1));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["ok"].as_bool(), Some(false));
    assert!(v["error"].as_str().unwrap().contains("bad.mdlod"), "{v}");
}

/// Spheres of sizes spanning two decades and more (an SPH run's smoothing lengths) are
/// noted with the modes that suit them; sizes within one decade are not.
#[test]
fn sizes_spanning_decades_suggest_a_projection() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, largest: f64| {
        let mut xyz = String::from("200\nProperties=species:S:1:pos:R:3:radius:R:1\n");
        for i in 0..200 {
            let r = 0.01 * (largest / 0.01f64).powf(i as f64 / 199.0);
            xyz.push_str(&format!("A {} {} {} {r}\n", i % 7, (i / 7) % 5, i / 35));
        }
        let path = dir.path().join(name);
        std::fs::write(&path, xyz).unwrap();
        let out = dir.path().join(format!("{name}.mdlod"));
        ok(&["convert", s(&path), "-o", s(&out)]);
        out
    };
    let png = dir.path().join("x.png");
    let wide = write("wide.xyz", 3.0);
    let out = ok(&[
        "render",
        s(&wide),
        "-o",
        s(&png),
        "--width",
        "64",
        "--height",
        "48",
    ]);
    assert!(
        out.contains("note: the particles' own sizes span 0.0100 to 3.00 (300×)")
            && out.contains("--mode splat"),
        "{out}"
    );
    let mut args = vec!["render", s(&wide), "-o", s(&png), "--mode", "splat"];
    args.extend(["--width", "64", "--height", "48"]);
    let out = ok(&args);
    assert!(
        out.contains("splats lit by their disks' area (π r²) let the largest outshine")
            && out.contains("--intensity attribute with a column of m / (π h²)"),
        "{out}"
    );
    // Splats are framed as the spheres are, their kernels' wings past the spheres
    // counting up to a twentieth of the data's size (they framed the whole reach of the
    // largest, 1.6× as far here).
    let distance = |mode: &str| {
        let view = dir.path().join(format!("{mode}.json"));
        let mut args = vec!["render", s(&wide), "-o", s(&png), "--mode", mode, "--ortho"];
        args.extend(["--width", "64", "--height", "48", "--save-view", s(&view)]);
        ok(&args);
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&view).unwrap()).unwrap();
        v["distance"].as_f64().unwrap()
    };
    let ratio = distance("splat") / distance("spheres");
    assert!((1.0..1.4).contains(&ratio), "{ratio}");
    // The density volume says how its fraction reads such sizes.
    let mut args = vec!["render", s(&wide), "-o", s(&png), "--mode", "density"];
    args.extend(["--width", "48", "--height", "32"]);
    let out = ok(&args);
    assert!(
        out.contains(
            "the volume fraction φ is each particle's sphere against spheres of the \
                      largest radius"
        ),
        "{out}"
    );
    let narrow = write("narrow.xyz", 0.05);
    let out = ok(&[
        "render",
        s(&narrow),
        "-o",
        s(&png),
        "--width",
        "64",
        "--height",
        "48",
    ]);
    assert!(!out.contains("own sizes span"), "{out}");
}

/// `--attribute-log10` with several columns keeps the first's logarithm and the others
/// as they are: splats light by the first's quantity, and colouring by another reads its
/// own values (not taken for a logarithm).
#[test]
fn a_logarithm_first_and_further_columns_as_they_are() {
    let dir = tempfile::tempdir().unwrap();
    let mut xyz = String::from("300\nProperties=species:S:1:pos:R:3:rho:R:1:T:R:1\n");
    for i in 0..300 {
        let rho = 10f64.powf(-8.0 + 10.0 * i as f64 / 299.0);
        xyz.push_str(&format!(
            "H {} {} {} {rho:e} {}\n",
            i % 7,
            (i / 7) % 6,
            i / 42,
            100 + i
        ));
    }
    let path = dir.path().join("sph.xyz");
    std::fs::write(&path, xyz).unwrap();
    let file = dir.path().join("sph.mdlod");
    ok(&[
        "convert",
        s(&path),
        "-o",
        s(&file),
        "--attribute",
        "rho",
        "--attribute",
        "T",
        "--attribute-log10",
    ]);
    let info = ok(&["info", s(&file)]);
    assert!(
        info.contains("log10(rho) in [-8, 2]") && info.contains("T in [100, 399]"),
        "{info}"
    );
    let png = dir.path().join("x.png");
    let base = ["--width", "48", "--height", "36"];
    let mut args = vec!["render", s(&file), "-o", s(&png), "--mode", "splat"];
    args.extend(["--intensity", "attribute", "--colour-map", "viridis"]);
    args.extend(base);
    let out = ok(&args);
    assert!(out.contains("the projected rho"), "{out}");
    let mut args = vec!["render", s(&file), "-o", s(&png), "--attribute", "T"];
    args.extend(["--colour-map", "viridis", "--log-scale"]);
    args.extend(base);
    let out = ok(&args);
    assert!(out.contains("T from 100 to 399"), "{out}");
}

/// `--attribute-log10=rho,sigma` keeps the logarithms of the columns named, the first and
/// a further one, and the others as they are: `info` lists them; colouring by the
/// further one by its own name reads its logarithms, and splats lit by it light by its
/// quantity; a name that is no --attribute column is refused, listing them, and a name
/// after a space, which `batch` would take for an input, is said to need the equals
/// sign.
#[test]
fn logarithms_of_named_columns_first_and_further() {
    let dir = tempfile::tempdir().unwrap();
    let mut xyz = String::from("300\nProperties=species:S:1:pos:R:3:rho:R:1:T:R:1:sigma:R:1\n");
    for i in 0..300 {
        let rho = 10f64.powf(-8.0 + 10.0 * i as f64 / 299.0);
        let sigma = 10f64.powf(-2.0 + 8.0 * ((i * 37) % 300) as f64 / 299.0);
        xyz.push_str(&format!(
            "H {} {} {} {rho:e} {} {sigma:e}\n",
            i % 7,
            (i / 7) % 6,
            i / 42,
            100 + i
        ));
    }
    let path = dir.path().join("sph.xyz");
    std::fs::write(&path, xyz).unwrap();
    let file = dir.path().join("sph.mdlod");
    let columns = [
        "--attribute",
        "rho",
        "--attribute",
        "T",
        "--attribute",
        "sigma",
    ];
    let mut args = vec!["convert", s(&path), "-o", s(&file)];
    args.extend(columns);
    args.push("--attribute-log10=rho,sigma");
    let out = ok(&args);
    assert!(!out.contains("decades"), "{out}");
    let info = ok(&["info", s(&file)]);
    assert!(
        info.contains("log10(rho) in [-8, 2]")
            && info.contains("T in [100, 399]")
            && info.contains("log10(sigma) in [-2, 6]"),
        "{info}"
    );
    let png = dir.path().join("x.png");
    let base = ["--width", "48", "--height", "36"];
    let mut args = vec!["render", s(&file), "-o", s(&png), "--attribute", "sigma"];
    args.extend(["--colour-map", "viridis"]);
    args.extend(base);
    let out = ok(&args);
    assert!(out.contains("log10(sigma) from -2 to 6"), "{out}");
    let mut args = vec!["render", s(&file), "-o", s(&png), "--mode", "splat"];
    args.extend(["--intensity", "attribute", "--attribute", "sigma"]);
    args.extend(["--colour-map", "viridis"]);
    args.extend(base);
    let out = ok(&args);
    assert!(out.contains("the projected sigma"), "{out}");
    // Ends given for the column by its own name are logarithms: said; by the stored
    // name, not.
    for (hide, says) in [("sigma=0.01:", true), ("log10(sigma)=0.01:", false)] {
        let out = ok(&[
            "render",
            s(&file),
            "-o",
            s(&png),
            "--width",
            "48",
            "--height",
            "36",
            "--hide-attribute",
            hide,
        ]);
        assert_eq!(
            out.contains(
                "note: --hide-attribute sigma=0.01:: sigma is kept as log10(sigma), so the \
                 range's ends are logarithms (0.01 stands for sigma = 1.02"
            ),
            says,
            "{out}"
        );
    }
    // A range of logarithms lights by the quantity less its low end, as a linear range
    // does; linear values typed for logarithms are refused, saying so.
    args.push("--attribute-range=2:3");
    let out = ok(&args);
    assert!(out.contains("the projected (sigma − 100)"), "{out}");
    args.pop();
    args.push("--attribute-range=0.01:1e4");
    let e = fails(&args);
    assert!(
        e.contains("the range's ends are logarithms too, and 10000 stands for 10^10000"),
        "{e}"
    );

    // A movie of a projection on a log scale maps the image's light, not the
    // logarithms (they were floored as if values from 0: "from 0.0067 to 6").
    let frames = dir.path().join("movie-frames");
    let mut args = vec!["batch", s(&path), "-o", s(&frames)];
    args.extend(columns);
    args.push("--attribute-log10=rho,sigma");
    ok(&args);
    // Scripts read which attributes are logarithms, of a file and of a batch alike.
    for of in [&file, &frames] {
        let v: serde_json::Value = serde_json::from_str(&ok(&["info", s(of), "--json"])).unwrap();
        assert_eq!(v["attribute"]["log10"], true, "{v}");
        assert_eq!(v["attributes"][0].get("log10"), None, "{v}");
        assert_eq!(v["attributes"][1]["log10"], true, "{v}");
    }
    let movie = dir.path().join("f-%03d.png");
    let mut args = vec!["render", s(&frames), "-o", s(&movie), "--mode", "splat"];
    args.extend(["--intensity", "attribute", "--attribute", "sigma"]);
    args.extend(["--colour-map", "viridis", "--log-scale"]);
    args.extend(base);
    let out = ok(&args);
    assert!(
        out.contains("rendered 1 frame") && !out.contains("smallest value above 0"),
        "{out}"
    );
    // A constant logarithm's note says its quantity too.
    let flat = dir.path().join("flat.xyz");
    let mut xyz = String::from("8\nProperties=species:S:1:pos:R:3:m:R:1\n");
    for i in 0..8 {
        xyz.push_str(&format!("H {} {} {} 3.54\n", i % 2, (i / 2) % 2, i / 4));
    }
    std::fs::write(&flat, xyz).unwrap();
    let flat_file = dir.path().join("flat.mdlod");
    ok(&[
        "convert",
        s(&flat),
        "-o",
        s(&flat_file),
        "--attribute",
        "m",
        "--attribute-log10",
    ]);
    let mut args = vec!["render", s(&flat_file), "-o", s(&png), "--mode", "splat"];
    args.extend(["--intensity", "attribute"]);
    args.extend(base);
    let out = ok(&args);
    assert!(
        out.contains("log10(m) is constant in this file (0.549") && out.contains(", m = 3.54):"),
        "{out}"
    );

    let mut args = vec!["convert", s(&path), "-o", s(&file)];
    args.extend(columns);
    args.push("--attribute-log10=");
    let e = fails(&args);
    assert!(e.contains("--attribute-log10= names no column"), "{e}");
    args.pop();
    args.push("--attribute-log10=sigma,nope");
    let e = fails(&args);
    assert!(
        e.contains("--attribute-log10=nope: nope is not a column --attribute names (those are rho, T, sigma)"),
        "{e}"
    );
    let out_dir = dir.path().join("frames");
    let mut args = vec!["batch", s(&path), "-o", s(&out_dir)];
    args.extend(columns);
    args.extend(["--attribute-log10", "sigma"]);
    let e = fails(&args);
    assert!(
        e.contains("sigma is taken as an input") && e.contains("(--attribute-log10=sigma)"),
        "{e}"
    );
}

/// A quoted pattern of files given to `convert` is said to be `batch`'s.
#[test]
fn convert_of_a_pattern_points_to_batch() {
    let dir = tempfile::tempdir().unwrap();
    let pattern = dir.path().join("dump.*.lammpstrj");
    let out = dir.path().join("x.mdlod");
    let e = fails(&["convert", s(&pattern), "-o", s(&out)]);
    assert!(
        e.contains("no such file: convert takes one file")
            && e.contains(&format!("`mdlod batch '{}' -o DIR`", pattern.display())),
        "{e}"
    );
}

/// An XYZ comment's `units=` is kept, and species read as elements in a unit that is not
/// ångströms are noted (silica colloids written `Si` in micrometres drew at 1.18 µm);
/// in ångström units, not.
#[test]
fn elements_in_micrometres_are_noted() {
    let dir = tempfile::tempdir().unwrap();
    for (units, says) in [("um", true), ("metal", false)] {
        let xyz = dir.path().join(format!("{units}.xyz"));
        std::fs::write(
            &xyz,
            format!(
                "4\nProperties=species:S:1:pos:R:3 units={units}\nSi 0 0 0\nSi 1 0 0\n\
                 Si 0 1 0\nSi 1 1 0\n"
            ),
        )
        .unwrap();
        let file = dir.path().join(format!("{units}.mdlod"));
        let out = ok(&["convert", s(&xyz), "-o", s(&file)]);
        assert_eq!(
            out.contains(
                "species Si (1.18): read as chemical elements, with their radii in ångströms, \
                 while the input's lengths are in µm: --radius Si=R gives each its size in µm"
            ),
            says,
            "{out}"
        );
        let info = ok(&["info", s(&file)]);
        assert!(info.contains(&format!("units        {units}")), "{info}");
    }
}

/// A movie of a batch that left out an empty frame (a focus lost) says its images are
/// numbered without it, so its time jumps there; a batch without gaps says nothing.
#[test]
fn a_movie_says_where_the_batch_left_frames_out() {
    let dir = tempfile::tempdir().unwrap();
    let frames: Vec<String> = (0..4)
        .map(|k| {
            let n = if k == 2 { 0 } else { 20 };
            let mut f = format!("{n}\nTime={}\n", 2.5 * k as f64);
            for i in 0..n {
                f.push_str(&format!("C {} {} {}\n", i % 3, (i / 3) % 3, i / 9));
            }
            f
        })
        .collect();
    for (name, text, says) in [
        ("gap", frames.concat(), true),
        (
            "whole",
            [&frames[..2], &frames[3..]].concat().concat(),
            false,
        ),
    ] {
        let xyz = dir.path().join(format!("{name}.xyz"));
        std::fs::write(&xyz, text).unwrap();
        let d = dir.path().join(format!("{name}.d"));
        ok(&["batch", s(&xyz), "-o", s(&d)]);
        let movie = dir.path().join(format!("{name}-%d.png"));
        let out = ok(&[
            "render",
            s(&d),
            "-o",
            s(&movie),
            "--width",
            "32",
            "--height",
            "24",
        ]);
        assert_eq!(
            out.contains(
                "note: the batch left out 1 frame without particles (timestep 2): the images \
                 are numbered without them, so the movie's time jumps there"
            ),
            says,
            "{out}"
        );
    }
}

/// A movie of one frame with values hidden maps the values drawn, as a still of that
/// frame does and as its legend says: the image took the file's whole range.
#[test]
fn a_movie_of_one_frame_maps_the_values_drawn_as_a_still() {
    let dir = tempfile::tempdir().unwrap();
    let mut xyz = String::from("300\nProperties=species:S:1:pos:R:3:q6:R:1\n");
    for i in 0..300 {
        let q6 = 0.04 + 0.55 * ((i * 37) % 300) as f64 / 299.0;
        xyz.push_str(&format!("C {} {} {} {q6}\n", i % 7, (i / 7) % 6, i / 42));
    }
    let path = dir.path().join("one.xyz");
    std::fs::write(&path, xyz).unwrap();
    let d = dir.path().join("one.d");
    ok(&["batch", s(&path), "-o", s(&d), "--attribute", "q6"]);
    let style = [
        "--width",
        "64",
        "--height",
        "48",
        "--hide-attribute",
        ":0.4",
        "--colour-map",
        "viridis",
    ];
    let movie = dir.path().join("m-%d.png");
    ok(&[&["render", s(&d), "-o", s(&movie)][..], &style[..]].concat());
    let m = mdlod_preprocess::batch::read_manifest(&d).unwrap();
    let still = dir.path().join("still.png");
    let frame = d.join(&m.frames[0].file);
    ok(&[&["render", s(&frame), "-o", s(&still)][..], &style[..]].concat());
    assert_eq!(
        std::fs::read(dir.path().join("m-0.png")).unwrap(),
        std::fs::read(&still).unwrap()
    );
}

/// Density volume fractions are of spheres of the largest radius: one stray large atom
/// beside a crystal of small ones makes their packing read high, said with the factor;
/// species of one size say nothing. The absorption is an optical depth.
#[test]
fn volume_fractions_of_mixed_radii_say_their_reference() {
    let dir = tempfile::tempdir().unwrap();
    let mut text = String::from(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n217\nITEM: BOX BOUNDS pp pp pp\n0 40\n\
         0 40\n0 40\nITEM: ATOMS id type x y z\n",
    );
    for i in 0..216 {
        let (x, y, z) = (i % 6, (i / 6) % 6, i / 36);
        text.push_str(&format!("{} 1 {} {} {}\n", i + 1, 2 * x, 2 * y, 2 * z));
    }
    text.push_str("217 2 30 30 30\n");
    let dump = dir.path().join("mixed.dump");
    std::fs::write(&dump, text).unwrap();
    let file = dir.path().join("mixed.mdlod");
    let png = dir.path().join("d.png");
    let render = |file: &Path| {
        ok(&[
            "render",
            s(file),
            "-o",
            s(&png),
            "--mode",
            "density",
            "--width",
            "32",
            "--height",
            "24",
        ])
    };
    for (big, says) in [("2=2", true), ("2=1", false)] {
        ok(&[
            "convert",
            s(&dump),
            "-o",
            s(&file),
            "--radius",
            "1=1",
            "--radius",
            big,
        ]);
        let out = render(&file);
        assert_eq!(
            out.contains(
                "volume fractions are of spheres of the largest radius, 2 (the density's \
                 reference): a particle of radius r adds 2/r times its own volume, so a close \
                 packing of species 1 (radius 1) reads 1.48"
            ),
            says,
            "{out}"
        );
        assert!(
            out.contains("optical depth 0.5 per radius at the top"),
            "{out}"
        );
    }
}

/// `--radius '*=R'` sizes every species no `--radius` names (it was refused as an unknown
/// species), in a conversion and in a batch, whose rerun redoes a frame when it changes.
#[test]
fn a_radius_for_every_species_not_named() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("sp.dump");
    std::fs::write(
        &dump,
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n4\nITEM: BOX BOUNDS pp pp pp\n0 10\n0 10\n\
         0 10\nITEM: ATOMS id type x y z\n1 1 1 1 1\n2 2 3 3 3\n3 3 5 5 5\n4 3 7 7 7\n",
    )
    .unwrap();
    let file = dir.path().join("sp.mdlod");
    ok(&[
        "convert",
        s(&dump),
        "-o",
        s(&file),
        "--radius",
        "*=0.3",
        "--radius",
        "2=1",
    ]);
    let radii: Vec<f32> = mdlod_format::MdlodFile::open(&file)
        .unwrap()
        .metadata()
        .species
        .iter()
        .map(|s| s.radius)
        .collect();
    assert_eq!(radii, [0.3, 1.0, 0.3]);
    let out = dir.path().join("b");
    let run = |r: &str| ok(&["batch", s(&dump), "-o", s(&out), "--radius", r]);
    assert!(run("*=0.3").contains("1 converted"));
    assert!(run("*=0.3").contains("0 converted, 1 already done"));
    assert!(run("*=0.4").contains("1 converted"));
}

/// Splats lit by a quantity whose logarithm the file keeps (a column density) add up to
/// the particles drawn, whatever range mdlod chose for them: with values hidden, the
/// image's light equals that of a file without the hidden particles. The light was
/// `σ − 10^lo` over the drawn particles' range (their smallest `lo`), 18-36 % low, with
/// no word.
#[test]
fn splats_of_a_logged_quantity_add_up_to_the_particles_drawn() {
    let dir = tempfile::tempdir().unwrap();
    let dump = |keep: &dyn Fn(f64) -> bool| {
        let mut rows = Vec::new();
        for i in 0..400u32 {
            let (x, y, z) = (i % 20, (i / 20) % 20, (i % 7) as f32 * 0.3);
            // Column densities from 1e-3 to 10.
            let sigma = 10f64.powf(-3.0 + 4.0 * f64::from(i) / 399.0);
            if keep(sigma) {
                rows.push(format!("{} 1 {x} {y} {z} {sigma:e}", i + 1));
            }
        }
        format!(
            "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{}\nITEM: BOX BOUNDS ff ff ff\n-1 21\n\
             -1 21\n-1 3\nITEM: ATOMS id type x y z sigma\n{}\n",
            rows.len(),
            rows.join("\n")
        )
    };
    let convert = |name: &str, text: String| {
        let path = dir.path().join(format!("{name}.dump"));
        std::fs::write(&path, text).unwrap();
        let file = dir.path().join(format!("{name}.mdlod"));
        ok(&[
            "convert",
            s(&path),
            "-o",
            s(&file),
            "--attribute",
            "sigma",
            "--attribute-log10",
            "--radius",
            "1=0.6",
        ]);
        file
    };
    let all = convert("all", dump(&|_| true));
    let dense = convert("dense", dump(&|sigma| sigma > 0.01));
    let view = dir.path().join("view.json");
    let flux = |file: &Path, more: &[&str]| -> f64 {
        let png = dir.path().join("s.png");
        let out = ok(&[
            &[
                "render",
                s(file),
                "-o",
                s(&png),
                "--mode",
                "splat",
                "--intensity",
                "attribute",
                "--ortho",
                "--look-along",
                "0,0,-1",
                "--width",
                "96",
                "--height",
                "96",
                "--screen-error",
                "0",
                "--json",
            ][..],
            more,
        ]
        .concat());
        let line = out.lines().find(|l| l.starts_with('{')).unwrap();
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        v["total_flux"].as_f64().unwrap()
    };
    let whole = flux(&all, &["--save-view", s(&view)]);
    let same = |a: f64, b: f64| (a / b - 1.0).abs() < 1e-4;
    // A hidden range holding no value: the drawn particles' range is the file's.
    let none_hidden = flux(&all, &["--view", s(&view), "--hide-attribute", "1e30:"]);
    assert!(same(none_hidden, whole), "{none_hidden} against {whole}");
    let hidden = flux(&all, &["--view", s(&view), "--hide-attribute", ":-2"]);
    let without = flux(&dense, &["--view", s(&view)]);
    assert!(same(hidden, without), "{hidden} against {without}");
    assert!(hidden < whole);
}

/// LIGGGHTS's `id type type x y z ... radius` (a column named twice, its copies equal)
/// converts from the first copy, noted; copies that differ are refused at the line where
/// they do, with the `sed` that renames the others (it was refused whatever the values).
#[test]
fn a_column_named_twice_is_read_where_its_copies_agree() {
    let dir = tempfile::tempdir().unwrap();
    let head = "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n3\nITEM: BOX BOUNDS pp ff ff\n0 1\n\
                0 1\n0 1\nITEM: ATOMS id type type x y z radius\n";
    let dump = dir.path().join("lig.dump");
    std::fs::write(
        &dump,
        format!("{head}1 1 1 0.2 0.5 0.5 0.05\n2 2 2 0.5 0.5 0.5 0.05\n3 1 1.0 0.8 0.5 0.5 0.05\n"),
    )
    .unwrap();
    let file = dir.path().join("lig.mdlod");
    let said = ok(&["convert", s(&dump), "-o", s(&file)]);
    assert!(
        said.contains(
            "lig.dump: `ITEM: ATOMS` names `type` (columns 2 and 3) more than once (as LIGGGHTS \
             writes `id type type`): the copies agree in all 3 atoms, and the first is read"
        ),
        "{said}"
    );
    let info = ok(&["info", s(&file)]);
    assert!(info.contains("2 particles"), "{info}");
    assert!(info.contains("1 particle\n"), "{info}");
    std::fs::write(
        &dump,
        format!("{head}1 1 1 0.2 0.5 0.5 0.05\n2 2 1 0.5 0.5 0.5 0.05\n3 1 1 0.8 0.5 0.5 0.05\n"),
    )
    .unwrap();
    let err = fails(&["convert", s(&dump), "-o", s(&file)]);
    assert!(
        err.contains(
            "lig.dump:11: column `type` is named 2 times (columns 2 and 3), and they differ \
             here (`2` in column 2, `1` in column 3)"
        ) && err.contains("ITEM: ATOMS id type type_2 x y z radius/'"),
        "{err}"
    );
}

/// Grains of their own sizes within one species (a DEM run's `radius` column) say the
/// reference too, by the smallest grain: a species' mean size hid it (the note was for
/// species of one size only).
#[test]
fn volume_fractions_of_grains_of_their_own_sizes_say_their_reference() {
    let dir = tempfile::tempdir().unwrap();
    let mut text = String::from(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n217\nITEM: BOX BOUNDS pp pp pp\n0 40\n\
         0 40\n0 40\nITEM: ATOMS id type x y z radius\n",
    );
    for i in 0..216 {
        let (x, y, z) = (i % 6, (i / 6) % 6, i / 36);
        text.push_str(&format!("{} 1 {} {} {} 0.5\n", i + 1, x, y, z));
    }
    text.push_str("217 1 30 30 30 2\n");
    let dump = dir.path().join("grains.dump");
    std::fs::write(&dump, text).unwrap();
    let file = dir.path().join("grains.mdlod");
    ok(&["convert", s(&dump), "-o", s(&file)]);
    let out = ok(&[
        "render",
        s(&file),
        "-o",
        s(&dir.path().join("d.png")),
        "--mode",
        "density",
        "--width",
        "32",
        "--height",
        "24",
    ]);
    assert!(
        out.contains(
            "volume fractions are of spheres of the largest radius, 2 (the density's \
             reference): a particle of radius r adds 2/r times its own volume, so a close \
             packing of particles of radius 0.5 (the smallest, of species 1) reads 2.96"
        ),
        "{out}"
    );
}

/// A conversion that keeps no attribute names the dump's columns it leaves behind, and
/// how to keep one (an OVITO user expects every column); keeping one says nothing.
#[test]
fn columns_left_behind_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("gb.mdlod");
    let dump = lammps_sample_path("cu_gb.cna.dump");
    let said = ok(&["convert", s(&dump), "-o", s(&out)]);
    assert!(
        said.contains(
            "note: the input's columns c_cna, c_cs, c_pe are not kept: --attribute c_cna keeps \
             one to colour, light or hide by (repeat it for more)"
        ),
        "{said}"
    );
    let said = ok(&["convert", s(&dump), "-o", s(&out), "--attribute", "c_pe"]);
    assert!(!said.contains("not kept"), "{said}");
}

/// A diverging map over values of one sign spreads them over the whole map where hidden
/// values make the range the drawn ones' (it was centred on 0, every atom one blue), and
/// a range centred on 0 over such values is noted as using half the map.
#[test]
fn a_diverging_map_over_values_of_one_sign() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("gb.mdlod");
    let dump = lammps_sample_path("cu_gb.cna.dump");
    ok(&[
        "convert",
        s(&dump),
        "-o",
        s(&file),
        "--attribute",
        "c_cna",
        "--attribute",
        "c_pe",
    ]);
    let png = dir.path().join("x.png");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "render",
            s(&file),
            "-o",
            s(&png),
            "--width",
            "48",
            "--height",
            "32",
        ];
        args.extend(["--attribute", "c_pe", "--colour-map", "cool-warm"]);
        args.extend(extra);
        ok(&args)
    };
    let out = run(&[
        "--hide-attribute",
        "c_cna=0.5:1.5",
        "--hide-attribute",
        "c_pe=:-3.5",
    ]);
    assert!(
        !out.contains("centred on 0") && !out.contains("diverging map"),
        "{out}"
    );
    let out = run(&["--attribute-range", "-4:4"]);
    assert!(
        out.contains("note: cool-warm is a diverging map, centred on 0, and c_pe is at or below 0"),
        "{out}"
    );
    // On a log scale it has no 0 to centre on: said.
    let out = run(&["--attribute-range", "-4:4", "--log-scale"]);
    assert!(
        out.contains(
            "note: cool-warm is a diverging map, centred on 0, but --log-scale has no 0 nor \
             negative values: c_pe's values at or below 0 all take its first colour"
        ),
        "{out}"
    );
}

/// A number with a decimal comma gets a tip with the point, whichever option takes it.
#[test]
fn a_decimal_comma_gets_a_tip() {
    for (option, value, tip) in [
        ("--zoom", "1,5", "--zoom 1.5"),
        ("--radius-scale", "0,8", "--radius-scale 0.8"),
    ] {
        let o = mdlod(&["render", "x.mdlod", "-o", "x.png", option, value]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert!(
            err.contains(&format!(
                "tip: numbers take a decimal point, not a comma: {tip}"
            )),
            "{err}"
        );
    }
}

/// A batch whose directory another batch holds exits with 75 (try again later), not
/// the 1 of a failure, and says who holds it.
#[test]
fn a_batch_held_by_another_exits_with_75() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    std::fs::create_dir(&out).unwrap();
    let lock = out.join(mdlod_preprocess::batch::lock_file_name(None));
    std::fs::write(&lock, "pid 4242 on node17").unwrap();
    let held = std::fs::File::open(&lock).unwrap();
    held.lock().unwrap();
    let dump = lammps_sample_path("cu_gb.cna.dump");
    let o = mdlod(&["batch", s(&dump), "-o", s(&out), "--json"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(75), "{err}");
    assert!(err.contains("(pid 4242 on node17)"), "{err}");
    // With --json, the refusal is a result too.
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["ok"].as_bool(), Some(false));
    assert!(
        v["error"].as_str().unwrap().contains("pid 4242 on node17"),
        "{v}"
    );
    drop(held);
    ok(&["batch", s(&dump), "-o", s(&out)]);
    // A movie of the directory while a batch (or a shard of one) rewrites it would mix
    // old and new frames: refused with 75 too.
    let held = std::fs::File::open(&lock).unwrap();
    held.lock_shared().unwrap();
    let movie = dir.path().join("m-%d.png");
    let o = mdlod(&[
        "render",
        s(&out),
        "-o",
        s(&movie),
        "--width",
        "32",
        "--height",
        "24",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(75), "{err}");
    assert!(
        err.contains("another mdlod batch is writing this directory"),
        "{err}"
    );
    drop(held);
    ok(&[
        "render",
        s(&out),
        "-o",
        s(&movie),
        "--width",
        "32",
        "--height",
        "24",
    ]);
}

/// A bus error (what the kernel sends where a mapped file is cut short while it is
/// read) ends the command with a message naming the files it was given and status 1,
/// not a silent death by the signal.
#[test]
fn a_bus_error_is_said_with_the_files_given() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("big.raw.json");
    let child = Command::new(env!("CARGO_BIN_EXE_mdlod"))
        .args([
            "generate", "crater", "-n", "50000000", "--format", "raw", "-o",
        ])
        .arg(&out)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(400));
    let killed = Command::new("kill")
        .args(["-BUS", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains(&format!(
            "a file in {} was cut short while mdlod read it",
            dir.path().display()
        )) || err.contains("a file this command reads was cut short"),
        "{err}"
    );
}

/// `--hide-attribute NAME=MIN:MAX` reads the attribute it names, so one image hides by
/// two columns at once: the fcc atoms of a CNA column and the low energies of another
/// leave the atoms neither hides (counted from the dump itself), a named range alone
/// draws what `--hide-by` does, a range that misses its column's values is noted with
/// the column, and bad names and too many ranges are refused.
#[test]
fn hidden_values_can_be_read_from_several_attributes_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("gb.mdlod");
    let dump = lammps_sample_path("cu_gb.cna.dump");
    ok(&[
        "convert",
        s(&dump),
        "-o",
        s(&file),
        "--attribute",
        "c_cna",
        "--attribute",
        "c_pe",
    ]);
    // (c_cna, c_pe) per atom, from the dump's text.
    let text = std::fs::read_to_string(&dump).unwrap();
    let atoms: Vec<(f64, f64)> = text
        .lines()
        .skip(9)
        .map(|l| {
            let f: Vec<f64> = l
                .split_whitespace()
                .skip(3)
                .map(|v| v.parse().unwrap())
                .collect();
            (f[3], f[5])
        })
        .collect();
    assert_eq!(atoms.len(), 2552);
    let png = dir.path().join("x.png");
    let drawn = |out: &str| -> u64 {
        let at = out.find(" particles").unwrap();
        out[..at].rsplit(' ').next().unwrap().parse().unwrap()
    };
    let render = |extra: &[&str]| {
        let mut args = vec!["render", s(&file), "-o", s(&png)];
        args.extend([
            "--width",
            "96",
            "--height",
            "64",
            "--screen-error",
            "0",
            "--no-occlusion",
        ]);
        args.extend(extra);
        ok(&args)
    };
    let out = render(&["--hide-attribute", "c_cna=0.5:1.5"]);
    assert_eq!(drawn(&out), 2552 - 2047, "{out}");
    let cut = -3.45;
    let out = render(&[
        "--hide-attribute",
        "c_cna=0.5:1.5",
        "--hide-attribute",
        "c_pe=:-3.45",
        "--attribute",
        "c_pe",
        "--colour-map",
        "viridis",
    ]);
    // A value within two 16-bit steps of the end may be stored on either side of it.
    let (lo, hi) = atoms.iter().fold((f64::MAX, f64::MIN), |(a, b), &(_, pe)| {
        (a.min(pe), b.max(pe))
    });
    let step = 2.0 * (hi - lo) / 65535.0;
    let shown = |margin: f64| {
        atoms
            .iter()
            .filter(|&&(cna, pe)| !(0.5..=1.5).contains(&cna) && pe > cut + margin)
            .count() as u64
    };
    let n = drawn(&out);
    assert!(
        (shown(step)..=shown(-step)).contains(&n) && n < 2552 - 2047,
        "{n} drawn, expected {}..={}: {out}",
        shown(step),
        shown(-step)
    );
    // A named range that misses every value says so, naming its column.
    let out = render(&[
        "--hide-attribute",
        "c_cna=0.5:1.5",
        "--hide-attribute",
        "c_pe=5:6",
    ]);
    assert!(
        out.contains("--hide-attribute (of c_pe) hides no particle"),
        "{out}"
    );
    assert_eq!(drawn(&out), 2552 - 2047, "{out}");
    // Turntables and movies say so too (a movie of the ranges over every frame).
    let spin = dir.path().join("spin-%d.png");
    let out = ok(&[
        "render",
        s(&file),
        "-o",
        s(&spin),
        "--width",
        "48",
        "--height",
        "32",
        "--turntable",
        "2",
        "--hide-attribute",
        "c_pe=5:6",
    ]);
    assert!(
        out.contains("--hide-attribute hides no particle: c_pe lies from"),
        "{out}"
    );
    let d = dir.path().join("gb.d");
    ok(&[
        "batch",
        s(&dump),
        "-o",
        s(&d),
        "--attribute",
        "c_cna",
        "--attribute",
        "c_pe",
    ]);
    let movie = dir.path().join("m-%d.png");
    let out = ok(&[
        "render",
        s(&d),
        "-o",
        s(&movie),
        "--width",
        "48",
        "--height",
        "32",
        "--hide-attribute",
        "c_cna=0.5:1.5",
        "--hide-attribute",
        "c_pe=5:6",
    ]);
    assert!(
        out.contains("--hide-attribute (of c_pe) hides no particle: c_pe lies from")
            && out.contains("in any frame"),
        "{out}"
    );
    for (extra, says) in [
        (vec!["--hide-attribute", "c_ke=1:2"], "c_cna, c_pe"),
        (
            vec!["--hide-attribute", "C_CNA=1:2"],
            "a name differs only in case: did you mean c_cna?",
        ),
        (
            vec!["--hide-attribute", "=1:2"],
            "the attribute's name before `=`",
        ),
        (vec!["--hide-attribute", "c_pe=1"], "expected MIN:MAX"),
        (
            vec!["--hide-by", "c_cna", "--hide-attribute", "c_pe=1:2"],
            "--hide-by has no effect without --hide-attribute MIN:MAX",
        ),
        (
            vec![
                "--hide-attribute",
                "c_pe=1:2",
                "--hide-attribute",
                "c_pe=3:4",
                "--hide-attribute",
                "c_cna=1:2",
                "--hide-attribute",
                "3:4",
                "--hide-attribute",
                "5:6",
            ],
            "at most 4 ranges",
        ),
    ] {
        let mut args = vec!["render", s(&file), "-o", s(&png)];
        args.extend(extra);
        let o = mdlod(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains(says), "{says}: {err}");
    }
}

/// `--frames` draws part of a movie with the whole movie's camera, colours and image
/// numbers, so pieces rendered apart join up: frames 2 to 4 come out as the whole
/// movie's images 2 to 4, byte for byte; `::2` every other one; bad selections refused.
#[test]
fn part_of_a_movie_is_the_same_as_in_the_whole_movie() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path().join("d");
    ok(&[
        "batch",
        s(&lammps_sample_path("cu_melt.custom.dump")),
        "-o",
        s(&d),
        "--attribute",
        "c_pe",
    ]);
    let render = |pattern: &Path, extra: &[&str]| {
        let mut args = vec![
            "render",
            s(&d),
            "-o",
            s(pattern),
            "--width",
            "128",
            "--height",
            "64",
        ];
        // (Each image's label its own frame's values.)
        args.extend([
            "--colour-map",
            "viridis",
            "--label",
            "{timestep} {frame} {time}",
        ]);
        args.extend(extra);
        ok(&args)
    };
    let whole = dir.path().join("whole-%d.png");
    render(&whole, &[]);
    let part = dir.path().join("part-%d.png");
    let out = render(&part, &["--frames", "2:5"]);
    assert!(
        out.contains("rendered 3 of the 6 frames (--frames)"),
        "{out}"
    );
    for k in 0..6 {
        let p = dir.path().join(format!("part-{k}.png"));
        assert_eq!(p.exists(), (2..5).contains(&k), "image {k}");
        if p.exists() {
            let w = dir.path().join(format!("whole-{k}.png"));
            assert_eq!(
                std::fs::read(&p).unwrap(),
                std::fs::read(&w).unwrap(),
                "image {k}"
            );
        }
    }
    // The last frame alone (time 1, written 1.0 as the whole movie's 0.2 steps are).
    let last = dir.path().join("last-%d.png");
    render(&last, &["--frames", "5:"]);
    assert_eq!(
        std::fs::read(dir.path().join("last-5.png")).unwrap(),
        std::fs::read(dir.path().join("whole-5.png")).unwrap()
    );
    let every = dir.path().join("every-%d.png");
    render(&every, &["--frames", "::2"]);
    let made: Vec<usize> = (0..6)
        .filter(|k| dir.path().join(format!("every-{k}.png")).exists())
        .collect();
    assert_eq!(made, [0, 2, 4]);
    // A projection's light range, which the first frame chose, is said, with how to
    // give one; given, it is not repeated.
    let proj = dir.path().join("proj-%d.png");
    let out = render(&proj, &["--mode", "splat"]);
    assert!(
        out.contains("light range ")
            && out.contains("(the first frame's; --light-range MIN:MAX gives one)"),
        "{out}"
    );
    let out = render(&proj, &["--mode", "splat", "--light-range", "0:5"]);
    assert!(!out.contains("(the first frame's;"), "{out}");
    for (sel, says) in [
        ("5:2", "END (2) must be above START (5)"),
        ("::0", "STEP must be 1 or more"),
        ("10:", "--frames selects none of the 6 frames"),
        ("a:b", "is no frame position"),
    ] {
        let x = dir.path().join("x-%d.png");
        let o = mdlod(&["render", s(&d), "-o", s(&x), "--frames", sel]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains(says), "{sel}: {err}");
    }
    let m = mdlod_preprocess::batch::read_manifest(&d).unwrap();
    let one = d.join(&m.frames[0].file);
    let o = mdlod(&[
        "render",
        s(&one),
        "-o",
        s(&dir.path().join("y.png")),
        "--frames",
        "0:1",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("--frames picks frames of a batch directory"),
        "{err}"
    );
}

/// `info DIR` of a sharded batch not merged yet says how far each shard is: the
/// frames each lists against those it owns, the shards with no manifest yet, and the
/// merge once every one is complete.
#[test]
fn info_of_an_unmerged_sharded_batch_shows_each_shards_progress() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path().join("d");
    let dump = lammps_sample_path("cu_melt.custom.dump");
    ok(&["batch", s(&dump), "-o", s(&d), "--shard", "0/2"]);
    let text = ok(&["info", s(&d)]);
    assert!(
        text.contains("a sharded batch, not merged yet (1 shard manifest)")
            && text.contains("shard 0 of 2  3 frames (complete)")
            && text.contains("no manifest yet: shard 1 of 2")
            && text.contains("once every shard is complete"),
        "{text}"
    );
    // Complete, but a shard built with another attribute: the merge would refuse it,
    // and so says `info` (it said the merge joins them).
    let other = dir.path().join("other");
    let args = ["--shard", "1/2", "--attribute", "c_pe"];
    ok(&[&["batch", s(&dump), "-o", s(&other)][..], &args[..]].concat());
    ok(&["batch", s(&dump), "-o", s(&other), "--shard", "0/2"]);
    let text = ok(&["info", s(&other)]);
    assert!(
        text.contains("every shard is complete, but a merge refuses them:"),
        "{text}"
    );
    ok(&["batch", s(&dump), "-o", s(&d), "--shard", "1/2"]);
    let text = ok(&["info", s(&d)]);
    assert!(
        text.contains("every shard is complete: `mdlod batch --merge"),
        "{text}"
    );
    let json: serde_json::Value = serde_json::from_str(&ok(&["info", s(&d), "--json"])).unwrap();
    assert_eq!(json["merged"], false);
    assert_eq!(json["shards"][1]["frames"], 3);
    assert_eq!(
        (&json["shard_counts"], &json["notes"]),
        (&serde_json::json!([2]), &serde_json::json!([]))
    );
    // A stray manifest of another sharding: the text's warning is in the JSON too.
    let stray = d.join("dataset.shard-0-of-3.json");
    std::fs::copy(d.join("dataset.shard-0-of-2.json"), &stray).unwrap();
    let mut m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stray).unwrap()).unwrap();
    m["shard"] = serde_json::json!([0, 3]);
    std::fs::write(&stray, m.to_string()).unwrap();
    let text = ok(&["info", s(&d)]);
    assert!(
        text.contains("note: the manifests are of different shard counts (2, 3)"),
        "{text}"
    );
    let json: serde_json::Value = serde_json::from_str(&ok(&["info", s(&d), "--json"])).unwrap();
    assert_eq!(json["shard_counts"], serde_json::json!([2, 3]));
    assert!(
        json["notes"][0]
            .as_str()
            .is_some_and(|n| n.contains("different shard counts (2, 3): a merge refuses them")),
        "{json}"
    );
    // A frame file a shard lists, moved away: a fault (exit 1, `ok` false), named, with
    // the shards' description and its notes still given.
    let listed: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(d.join("dataset.shard-1-of-2.json")).unwrap(),
    )
    .unwrap();
    let moved = d.join(listed["frames"][0]["file"].as_str().unwrap());
    let aside = dir.path().join("aside.mdlod");
    std::fs::rename(&moved, &aside).unwrap();
    let out = mdlod(&["info", s(&d), "--json"]);
    assert_eq!(out.status.code(), Some(1));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["ok"], false);
    assert_eq!(json["missing_files"].as_array().unwrap().len(), 1);
    assert!(json["error"]
        .as_str()
        .unwrap()
        .contains("the shards list is not there"));
    assert!(json["notes"][0]
        .as_str()
        .unwrap()
        .contains("different shard counts"));
    let e = fails(&["info", s(&d)]);
    assert!(
        e.contains("1 frame file the shards list is not there"),
        "{e}"
    );
    std::fs::rename(&aside, &moved).unwrap();
    std::fs::remove_file(&stray).unwrap();
    ok(&["batch", "--merge", s(&d)]);
    let text = ok(&["info", s(&d)]);
    assert!(text.contains("frames       6"), "{text}");
}

/// A shard run beside shard manifests of another array size says at its start that
/// `--merge` will refuse the two (a failed task resubmitted alone runs as shard 0 of 1).
#[test]
fn a_shard_of_another_sharding_is_noted_before_it_converts() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path().join("d");
    let dump = lammps_sample_path("cu_melt.custom.dump");
    ok(&["batch", s(&dump), "-o", s(&d), "--shard", "0/2"]);
    let out = ok(&["batch", s(&dump), "-o", s(&d), "--shard", "1/2"]);
    assert!(!out.contains("holds shard manifests of"), "{out}");
    let out = ok(&["batch", s(&dump), "-o", s(&d), "--shard", "0/1"]);
    assert!(
        out.contains("holds shard manifests of 2 shards; this run is shard 0 of 1")
            && out.contains("give it its place in the whole array with --shard K/N"),
        "{out}"
    );
}

/// Convert once, then delete the dumps: a rerun over the dumps left says which frames of
/// deleted dumps stay listed, and movies and verify keep them.
#[test]
fn a_rerun_after_deleting_dumps_keeps_their_frames_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(lammps_sample_path("cu_melt.custom.dump")).unwrap();
    let (units, _) = text.split_once("ITEM: TIME\n").unwrap();
    let mut files = Vec::new();
    for frame in text.split("ITEM: TIME\n").skip(1) {
        let (_, rest) = frame.split_once("ITEM: TIMESTEP\n").unwrap();
        let timestep: u64 = rest.lines().next().unwrap().trim().parse().unwrap();
        let p = dir.path().join(format!("melt.{timestep}.dump"));
        std::fs::write(&p, format!("{units}ITEM: TIME\n{frame}")).unwrap();
        files.push(p);
    }
    let out = dir.path().join("out");
    let pattern = dir.path().join("melt.*.dump");
    ok(&["batch", s(&pattern), "-o", s(&out)]);
    std::fs::remove_file(&files[0]).unwrap();
    std::fs::remove_file(&files[1]).unwrap();
    let text = ok(&["batch", s(&pattern), "-o", s(&out)]);
    assert!(
        text.contains(
            "note: 2 frames converted from dumps that are gone since stay listed (timesteps \
             0, 100)"
        ),
        "{text}"
    );
    let text = ok(&["verify", s(&out)]);
    assert!(text.contains("ok: 6 frames"), "{text}");
    // Other settings: the deleted dumps' frames are kept on disk, unlisted, and said so.
    ok(&["batch", s(&pattern), "-o", s(&out), "--radius", "1=1.5"]);
    let text = ok(&["info", s(&out)]);
    assert!(
        text.contains("unlisted     2 frames of deleted dumps"),
        "{text}"
    );
    let json: serde_json::Value = serde_json::from_str(&ok(&["info", s(&out), "--json"])).unwrap();
    assert_eq!(json["unlisted"].as_array().map(Vec::len), Some(2));
    // Run from elsewhere, over dumps named by other paths: the recorded relative paths
    // are found beside the inputs, so a dump left out is no dump gone.
    let run = |cwd: &Path, args: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_mdlod"))
            .args(args)
            .current_dir(cwd)
            .env("WGPU_BACKEND", "vulkan")
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8(o.stdout).unwrap()
    };
    let rel = dir.path().join("rel");
    std::fs::create_dir(&rel).unwrap();
    let dumps = rel.join("dumps");
    std::fs::create_dir(&dumps).unwrap();
    for f in &files[2..] {
        std::fs::copy(f, dumps.join(f.file_name().unwrap())).unwrap();
    }
    run(&rel, &["batch", "dumps/melt.*.dump", "-o", "out"]);
    let text = run(
        Path::new("/"),
        &[
            "batch",
            s(&dumps.join("melt.300.dump")),
            "-o",
            s(&rel.join("out")),
        ],
    );
    assert!(!text.contains("are gone since"), "{text}");
    assert!(
        text.contains("belong to no frame of these inputs"),
        "{text}"
    );
}

/// An in-image key asks room for the species a hidden value range leaves any particle
/// of, not for every species of the file (30 species, 2 shown, fit a small image).
#[test]
fn an_in_image_key_asks_room_for_the_species_left_shown() {
    let dir = tempfile::tempdir().unwrap();
    let xyz = dir.path().join("many.xyz");
    let lines: Vec<String> = (0..600)
        .map(|i| {
            let s = i % 30;
            let p = |k: u32| ((i * 7 + k * 13) % 200) as f32 / 10.0;
            format!("S{s} {} {} {} {s}", p(0), p(1), p(2))
        })
        .collect();
    std::fs::write(
        &xyz,
        format!(
            "{}\nProperties=species:S:1:pos:R:3:q:R:1\n{}\n",
            lines.len(),
            lines.join("\n")
        ),
    )
    .unwrap();
    let file = dir.path().join("many.mdlod");
    ok(&["convert", s(&xyz), "-o", s(&file), "--attribute", "q"]);
    let png = dir.path().join("many.png");
    let base = [
        "render",
        s(&file),
        "-o",
        s(&png),
        "--width",
        "320",
        "--height",
        "240",
    ];
    let e = fails(&[&base[..], &["--legend-in-image"]].concat());
    assert!(e.contains("cannot hold the legend"), "{e}");
    let text = ok(&[&base[..], &["--hide-attribute", "2:", "--legend-in-image"]].concat());
    assert!(
        text.contains("legend drawn into") && text.contains("2 species"),
        "{text}"
    );
}

/// A box past single precision's range (a damaged header's 1e39) converts with a note,
/// draws without its cell, and `--cell` is refused naming the file and the box (it
/// panicked in the sort framing the cell's corners).
#[test]
fn a_box_past_single_precision_is_noted_and_not_drawn() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("huge.dump");
    std::fs::write(
        &dump,
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n2\nITEM: BOX BOUNDS pp pp pp\n0 1e39\n0 10\n0 10\nITEM: ATOMS id type x y z\n1 1 1 1 1\n2 1 2 2 2\n",
    )
    .unwrap();
    let file = dir.path().join("huge.mdlod");
    let out = ok(&["convert", s(&dump), "-o", s(&file)]);
    assert!(out.contains("note: the box reaches 1.000e39"), "{out}");
    let png = dir.path().join("h.png");
    let size = ["--width", "32", "--height", "24"];
    ok(&[&["render", s(&file), "-o", s(&png)][..], &size].concat());
    let e = fails(&[&["render", s(&file), "-o", s(&png), "--cell"][..], &size].concat());
    assert!(
        e.contains("--cell: ") && e.contains("huge.mdlod: the file's box") && e.contains("1e39"),
        "{e}"
    );
}

/// A small file damaged on disk (one byte of its positions flipped) is refused when it is
/// drawn, naming the section, not drawn from the damaged bytes (opening checks no
/// per-particle data; a file this small is checked whole).
#[test]
fn a_small_file_damaged_on_disk_is_refused_when_drawn() {
    let dir = tempfile::tempdir().unwrap();
    let file = converted(dir.path(), "cu_melt.custom.dump");
    let positions = MdlodFile::open(&file)
        .unwrap()
        .sections()
        .iter()
        .rfind(|s| {
            mdlod_format::layout::SectionKind::from_code(s.kind)
                .is_some_and(|k| k.name() == "POSITIONS")
        })
        .map(|s| s.offset as usize + 7)
        .unwrap();
    let mut bytes = std::fs::read(&file).unwrap();
    bytes[positions] ^= 0x10;
    std::fs::write(&file, bytes).unwrap();
    ok(&["info", s(&file)]);
    let png = dir.path().join("x.png");
    let e = fails(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--width",
        "32",
        "--height",
        "24",
    ]);
    assert!(
        e.contains("(POSITIONS, level") && e.contains("checksum mismatch") && e.contains("a.mdlod"),
        "{e}"
    );
    assert!(!png.exists());
}

/// On a still of elements, an element's symbol in another case (`li`) is a misspelling,
/// refused with the symbol, even where the frame lacks that element; the symbol itself
/// is noted as absent (ions that come later).
#[test]
fn an_elements_symbol_in_another_case_is_refused_where_the_frame_lacks_it() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("cho.dump");
    std::fs::write(
        &dump,
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n3\nITEM: BOX BOUNDS pp pp pp\n0 10\n0 10\n0 10\nITEM: ATOMS id element x y z\n1 C 1 1 1\n2 H 2 2 2\n3 O 3 3 3\n",
    )
    .unwrap();
    let file = dir.path().join("cho.mdlod");
    ok(&["convert", s(&dump), "-o", s(&file)]);
    let png = dir.path().join("x.png");
    let size = ["--width", "32", "--height", "24"];
    let e = fails(
        &[
            &[
                "render",
                s(&file),
                "-o",
                s(&png),
                "--species-colour",
                "li=red",
            ][..],
            &size,
        ]
        .concat(),
    );
    assert!(
        e.contains("no species named \"li\"; did you mean \"Li\"?"),
        "{e}"
    );
    let out = ok(&[
        &[
            "render",
            s(&file),
            "-o",
            s(&png),
            "--species-colour",
            "Li=red",
        ][..],
        &size,
    ]
    .concat());
    assert!(out.contains("no particle of this frame is Li"), "{out}");
}

/// A small file damaged so that every checksum still holds (a crafted file: a particle's
/// quantized position moved far outside its cluster, all checksums recomputed) is
/// refused when drawn, as `verify` refuses it, not drawn from the damaged data.
#[test]
fn a_small_crafted_file_with_right_checksums_is_refused_when_drawn() {
    let dir = tempfile::tempdir().unwrap();
    let file = converted(dir.path(), "cu_melt.custom.dump");
    let u64_at = |b: &[u8], at: usize| u64::from_le_bytes(b[at..at + 8].try_into().unwrap());
    let mut b = std::fs::read(&file).unwrap();
    let (count, table) = (
        u32::from_le_bytes(b[16..20].try_into().unwrap()) as usize,
        u64_at(&b, 24) as usize,
    );
    let entry = (0..count)
        .map(|i| table + 32 * i)
        .rfind(|&e| {
            mdlod_format::layout::SectionKind::from_code(u32::from_le_bytes(
                b[e..e + 4].try_into().unwrap(),
            ))
            .is_some_and(|k| k.name() == "POSITIONS")
        })
        .unwrap();
    let (offset, length) = (
        u64_at(&b, entry + 8) as usize,
        u64_at(&b, entry + 16) as usize,
    );
    // The first particle's x moved to the far end of its cluster's quantization range,
    // and back along it: outside the cluster's bounds.
    b[offset..offset + 2].copy_from_slice(&[0xff, 0xff]);
    b[offset + 2..offset + 4].copy_from_slice(&[0x00, 0x00]);
    let sum = xxhash_rust::xxh3::xxh3_64(&b[offset..offset + length]);
    b[entry + 24..entry + 32].copy_from_slice(&sum.to_le_bytes());
    let table_sum = xxhash_rust::xxh3::xxh3_64(&b[table..table + 32 * count]);
    b[40..48].copy_from_slice(&table_sum.to_le_bytes());
    let header_sum = xxhash_rust::xxh3::xxh3_64(&b[..56]);
    b[56..64].copy_from_slice(&header_sum.to_le_bytes());
    std::fs::write(&file, &b).unwrap();
    let said = fails(&["verify", s(&file)]);
    let png = dir.path().join("x.png");
    let e = fails(&[
        "render",
        s(&file),
        "-o",
        s(&png),
        "--width",
        "32",
        "--height",
        "24",
    ]);
    assert!(
        e.contains("a.mdlod: level 1, particle 0: decodes") && said.contains("particle 0: decodes"),
        "{e} (verify: {said})"
    );
    assert!(!png.exists());
}

/// A granular run's dump (own diameters, a kinetic energy spanning decades) through the
/// mistakes and choices a newcomer makes:
/// - `--radius` for a type of own sizes is noted (it replaces them; some read it as a
///   default or a scale), and not for a type whose radius it does not change;
/// - a further `--attribute` gets the first's note of values below a step;
/// - a batch says a note that differs from frame to frame in its figures once;
/// - a rerun names the settings that changed;
/// - an image's name for `convert -o`, and a second file name without `-o`, are refused
///   with what to type instead.
#[test]
fn a_granular_newcomers_choices_and_mistakes_are_answered() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("pour.dump");
    let mut text = String::new();
    for frame in 0..3u32 {
        text.push_str(&format!(
            "ITEM: TIMESTEP\n{}\nITEM: NUMBER OF ATOMS\n60\nITEM: BOX BOUNDS pp pp ff\n\
             0 10\n0 10\n0 20\nITEM: ATOMS id type diameter x y z c_ke\n",
            frame * 500
        ));
        for i in 0..60u32 {
            let d = if i % 2 == 0 {
                0.6 + 0.005 * i as f32
            } else {
                1.1
            };
            // Grains at rest (0) and energies over 9 + frame decades.
            let ke = if i < 10 {
                0.0
            } else {
                10f64.powf(1.0 - (i as f64 / 60.0) * (9.0 + frame as f64))
            };
            text.push_str(&format!(
                "{} {} {d} {} {} {} {ke:e}\n",
                i + 1,
                1 + i % 2,
                (i % 10) as f32,
                (i / 10) as f32,
                1.0 + frame as f32
            ));
        }
    }
    std::fs::write(&dump, text).unwrap();
    let file = dir.path().join("pour.mdlod");
    let out = ok(&[
        "convert",
        s(&dump),
        "-o",
        s(&file),
        "--radius",
        "1=0.4",
        "--radius",
        "2=0.55",
        "--attribute",
        "x",
        "--attribute",
        "c_ke",
    ]);
    assert!(
        out.contains(
            "note: species 1: --radius 1=0.4 draws every particle of it at radius 0.4, in place \
             of the sizes the input gives its particles (radii 0.3 to 0.445)"
        ),
        "{out}"
    );
    // Type 2's grains are all of radius 0.55: nothing replaced.
    assert!(!out.contains("species 2:"), "{out}");
    assert!(
        out.contains("note: attribute c_ke: ") && out.contains("lie below one 16-bit step"),
        "{out}"
    );

    // A batch: the energy's note once, with the frames that have it.
    let d = dir.path().join("pour.d");
    let out = ok(&["batch", s(&dump), "-o", s(&d), "--attribute", "c_ke"]);
    let lines: Vec<&str> = out
        .lines()
        .filter(|l| l.contains("attribute c_ke"))
        .collect();
    assert_eq!(lines.len(), 1, "{out}");
    assert!(
        lines[0].contains("(the figures are timestep 0's; 3 frames have this note"),
        "{out}"
    );
    // Every info JSON says what it describes.
    for (path, kind) in [(&file, "mdlod"), (&d, "batch")] {
        let v: serde_json::Value = serde_json::from_str(&ok(&["info", s(path), "--json"])).unwrap();
        assert_eq!(v["kind"], kind, "{v}");
    }
    // Reruns name what changed.
    let out = ok(&["batch", s(&dump), "-o", s(&d)]);
    assert!(
        out.contains("3 built with other settings (--attribute)"),
        "{out}"
    );
    let out = ok(&["batch", s(&dump), "-o", s(&d), "--radius", "2=0.7"]);
    // Notes about two numbered species are both said (not merged as one note whose
    // figures differ).
    let both = dir.path().join("both.d");
    let notes = ok(&[
        "batch",
        s(&dump),
        "-o",
        s(&both),
        "--radius",
        "1=0.4",
        "--radius",
        "2=0.7",
    ]);
    assert!(
        notes.contains("note: species 1: --radius 1=0.4")
            && notes.contains("note: species 2: --radius 2=0.7"),
        "{notes}"
    );
    assert!(
        out.contains("3 built with other settings (--radius)"),
        "{out}"
    );
    let out = ok(&[
        "batch",
        s(&dump),
        "-o",
        s(&d),
        "--attribute",
        "c_ke",
        "--radius",
        "2=0.8",
    ]);
    assert!(
        out.contains("3 built with other settings (--radius, --attribute)"),
        "{out}"
    );

    // A radius given by the name a rename takes away: refused before any frame is
    // converted (it was refused at the end, every frame rebuilt without it).
    let renamed = dir.path().join("renamed.d");
    let err = fails(&[
        "batch",
        s(&dump),
        "-o",
        s(&renamed),
        "--radius",
        "2=0.7",
        "--species-name",
        "2=big",
    ]);
    assert!(
        err.contains("--radius takes the new name: --radius big=0.7"),
        "{err}"
    );
    assert!(!renamed.exists());

    // An image's name for the file convert writes.
    let png = dir.path().join("pour.png");
    let err = fails(&["convert", s(&dump), "-o", s(&png)]);
    assert!(
        err.contains("convert writes a .mdlod file, not an image")
            && err.contains(&format!("`mdlod render {} -o {}`", s(&file), s(&png))),
        "{err}"
    );
    assert!(!png.exists());
    let xyz = dir.path().join("pour.xyz");
    let err = fails(&["convert", s(&dump), "-o", s(&xyz)]);
    assert!(err.contains("this is a dump's name; write"), "{err}");
    assert!(!xyz.exists());
    let txt = dir.path().join("pour.txt");
    let err = fails(&["convert", s(&dump), "-o", s(&txt)]);
    assert!(
        err.contains("convert writes a binary .mdlod file, and this names a file of another kind"),
        "{err}"
    );
    assert!(!txt.exists());
    // A still from a batch directory, and a directory without a manifest.
    let err = fails(&["render", s(&d), "-o", s(&png)]);
    assert!(
        err.contains("rendered from its file in the directory, frame-<timestep>.mdlod"),
        "{err}"
    );
    let err = fails(&["info", s(dir.path())]);
    assert!(
        err.contains("a directory is described as the frames of a batch, listed in its dataset.json; there is none here"),
        "{err}"
    );
    // The output without -o.
    let err = fails(&["convert", s(&dump), s(&file)]);
    assert!(
        err.contains(&format!(
            "tip: the file to write goes after -o: mdlod convert ... -o {}",
            s(&file)
        )),
        "{err}"
    );
}

/// A single-frame file of a set whose timestep cannot be read fails alone with
/// --keep-going: numbered by its place in the set (3), it took the timestep of a real
/// frame (3) and the whole batch stopped on a duplicate. Without --keep-going it is the
/// batch's error, naming it.
#[test]
fn an_unreadable_timestep_in_a_set_fails_alone() {
    let dir = tempfile::tempdir().unwrap();
    let set = dir.path().join("set");
    std::fs::create_dir(&set).unwrap();
    for (name, step) in [
        ("a.0.dump", "0"),
        ("a.100.dump", "100"),
        ("a.200.dump", "200"),
        ("a.300.dump", "abc"),
        ("a.500.dump", "3"),
    ] {
        let mut text = format!(
            "ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ATOMS\n8\nITEM: BOX BOUNDS pp pp pp\n\
             0 4\n0 4\n0 4\nITEM: ATOMS id type x y z\n"
        );
        for i in 0..8 {
            text.push_str(&format!("{} 1 {} {} {}\n", i + 1, i % 2, i / 2 % 2, i / 4));
        }
        std::fs::write(set.join(name), text).unwrap();
    }
    let pattern = set.join("a.*.dump");
    let out = dir.path().join("b");
    let err = fails(&["batch", s(&pattern), "-o", s(&out), "--keep-going"]);
    assert!(
        err.contains("a.300.dump:2: malformed `ITEM: TIMESTEP` value `abc`")
            && !err.contains("appears twice"),
        "{err}"
    );
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("dataset.json")).unwrap()).unwrap();
    let steps: Vec<u64> = manifest["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["timestep"].as_u64().unwrap())
        .collect();
    assert_eq!(steps, [0, 3, 100, 200]);
    let failed = manifest["failed"].as_array().unwrap();
    assert_eq!(failed.len(), 1);
    assert!(failed[0].get("timestep").is_none(), "{failed:?}");
    let out2 = dir.path().join("b2");
    let err = fails(&["batch", s(&pattern), "-o", s(&out2)]);
    assert!(
        err.contains("malformed `ITEM: TIMESTEP` value `abc`"),
        "{err}"
    );
    // A frame with no timestep of its own numbered onto a real one: said so, not taken
    // for a restart (whose way out would drop one of them).
    let xyz = dir.path().join("w.xyz");
    std::fs::write(
        &xyz,
        "2\nProperties=species:S:1:pos:R:3\nCu 0 0 0\nCu 1 1 1\n",
    )
    .unwrap();
    // (Its place is 2, after c.dump's and a.0.dump's frames: c.dump's timestep.)
    let c = dir.path().join("c.dump");
    let text = std::fs::read_to_string(set.join("a.0.dump")).unwrap();
    std::fs::write(&c, text.replacen("TIMESTEP\n0\n", "TIMESTEP\n2\n", 1)).unwrap();
    let out3 = dir.path().join("b3");
    let err = fails(&[
        "batch",
        s(&c),
        s(&set.join("a.0.dump")),
        s(&xyz),
        "-o",
        s(&out3),
    ]);
    assert!(
        err.contains("w.xyz frame 0 records no timestep and is numbered by its place")
            && !err.contains("--duplicate-timesteps"),
        "{err}"
    );
    // A quoted pattern over directories: said so (it was "No such file or directory").
    let across = dir.path().join("s*").join("a.0.dump");
    let err = fails(&["batch", s(&across), "-o", s(&out3)]);
    assert!(
        err.contains("matches file names in one directory, not directory names"),
        "{err}"
    );
}

/// `batch --index-only`: lists the frames and keeps the text dumps' index, converting
/// nothing; the run after it scans no dump (its JSON says so), and `--shard` with it is
/// refused.
#[test]
fn batch_index_only_keeps_the_frame_index_for_the_runs_after_it() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("melt.dump");
    std::fs::copy(lammps_sample_path("cu_melt.custom.dump"), &input).unwrap();
    let out = dir.path().join("run.d");
    // A dump modified moments ago is scanned and not kept, and said so.
    let said = ok(&["batch", s(&input), "-o", s(&out), "--index-only"]);
    assert!(
        said.contains("6 frames in 1 input; no frame index kept")
            && said.contains("note: 1 file scanned but not kept in the index"),
        "{said}"
    );
    std::thread::sleep(std::time::Duration::from_millis(2100));
    let said = ok(&["batch", s(&input), "-o", s(&out), "--index-only"]);
    assert!(
        said.contains("6 frames in 1 input; the frame index of 1 text file kept in")
            && said.contains("(1 scanned, 0 unchanged since they were)"),
        "{said}"
    );
    assert!(out.join(".dataset.index.json").is_file());
    assert!(!out.join("dataset.json").exists());
    // info of it says what it holds: an index, no frame yet.
    let err = fails(&["info", s(&out)]);
    assert!(
        err.contains(
            "whose inputs are indexed (.dataset.index.json) but of which no frame is converted yet"
        ),
        "{err}"
    );
    let said = ok(&[
        "batch",
        s(&input),
        "-o",
        s(&out),
        "--json",
        "--threads",
        "1",
    ]);
    let json: serde_json::Value = serde_json::from_str(said.lines().last().unwrap()).unwrap();
    assert_eq!(json["converted"], 6, "{json}");
    assert_eq!(json["index"]["from_cache"], 1, "{json}");
    assert_eq!(json["index"]["scanned"], 0, "{json}");
    assert!(
        json["index"]["file"]
            .as_str()
            .is_some_and(|f| f.ends_with(".dataset.index.json")),
        "{json}"
    );
    // No text dump to index: no index file named, as none is written.
    let gsd_out = dir.path().join("gsd.d");
    let gsd = mdlod_datasets::gsd_sample_path("hoomd_mixture.gsd");
    let said = ok(&["batch", s(&gsd), "-o", s(&gsd_out), "--json"]);
    let json: serde_json::Value = serde_json::from_str(said.lines().last().unwrap()).unwrap();
    assert!(json["index"]["file"].is_null(), "{json}");
    assert_eq!(json["index"]["not_indexed"], 1, "{json}");
    assert!(!gsd_out.join(".dataset.index.json").exists());
    let err = fails(&[
        "batch",
        s(&input),
        "-o",
        s(&out),
        "--index-only",
        "--shard",
        "0/2",
    ]);
    assert!(err.contains("--shard"), "{err}");
}

/// A file set whose newest file a running simulation has just opened, still empty: it
/// is left for a rerun, counted apart from the frames, so that the summary's counts add
/// up and nothing is called cut short.
#[test]
fn batch_of_a_set_whose_newest_file_is_empty_counts_it_apart_from_the_frames() {
    let dir = tempfile::tempdir().unwrap();
    let all = dir.path().join("all.lammpstrj");
    generate(&["crater", "-n", "500", "--frames", "2"], &all);
    let text = std::fs::read_to_string(&all).unwrap();
    let second = text.match_indices("ITEM: TIMESTEP").nth(1).unwrap().0;
    let set = dir.path().join("set");
    std::fs::create_dir(&set).unwrap();
    std::fs::write(set.join("dump.0.lammpstrj"), &text[..second]).unwrap();
    std::fs::write(set.join("dump.100.lammpstrj"), &text[second..]).unwrap();
    std::fs::write(set.join("dump.200.lammpstrj"), "").unwrap();
    let d = dir.path().join("d");
    let out = ok(&["batch", s(&set.join("dump.*.lammpstrj")), "-o", s(&d)]);
    assert!(
        out.contains(
            "2 frames in the inputs (and an input still empty, left for a rerun): 2 \
             converted, 0 already done;"
        ) && out.contains("dump.200.lammpstrj, the newest input, is empty")
            && !out.contains("cut short"),
        "{out}"
    );
}

/// Values an audit of the command line found accepted wrongly: a demo refusing its
/// particle count after it had emptied the last dump, `generate` replacing a converted
/// file given as `-o`, a malformed `--shard` exiting as a failure rather than a command
/// line that cannot be parsed (2), thread counts and sizes beyond any machine.
#[test]
fn values_no_command_can_use_are_refused_before_anything_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let demo = dir.path().join("demo");
    std::fs::create_dir_all(&demo).unwrap();
    let dump = demo.join("crater.lammpstrj");
    std::fs::write(&dump, "kept").unwrap();
    let out = mdlod(&["demo", "--particles", "0", "--dir", s(&demo)]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--particles"));
    assert_eq!(std::fs::read(&dump).unwrap(), b"kept");
    let e = fails(&["demo", "--dir", s(&dump)]);
    assert!(e.contains("exists and is not a directory"), "{e}");

    let src = dir.path().join("c.lammpstrj");
    generate(&["crater", "-n", "300"], &src);
    let converted = dir.path().join("c.mdlod");
    ok(&["convert", s(&src), "-o", s(&converted)]);
    let before = std::fs::read(&converted).unwrap();
    let e = fails(&["generate", "crater", "-n", "10", "-o", s(&converted)]);
    assert!(e.contains("exists and is a .mdlod file"), "{e}");
    assert_eq!(std::fs::read(&converted).unwrap(), before);

    // Conversion settings given to a merge, which converts nothing.
    let e = fails(&["batch", "--merge", s(dir.path()), "--radius", "1=9"]);
    assert!(e.contains("--radius given with --merge"), "{e}");
    for args in [
        vec!["batch", s(&src), "-o", "d", "--shard", "a/b"],
        vec!["convert", s(&src), "-o", "t.mdlod", "--threads", "100000"],
        vec![
            "convert",
            s(&src),
            "-o",
            "t.mdlod",
            "--memory-limit",
            "18446744073709551616",
        ],
    ] {
        let out = mdlod(&args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
    }
}

/// `info --json` that fails ends with the one JSON object every `--json` command gives
/// on failure, `ok` false with the error: it printed nothing on standard output.
#[test]
fn info_json_that_fails_says_so_in_json() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.mdlod");
    let out = mdlod(&["info", s(&missing), "--json"]);
    assert_eq!(out.status.code(), Some(1));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["ok"], false);
    assert!(
        v["error"].as_str().unwrap().contains("missing.mdlod"),
        "{v}"
    );
}

/// A LAMMPS text dump of `positions` (one type) with an optional `radius` column, in a
/// fixed box around them.
fn awkward_dump(path: &Path, positions: &[[f64; 3]], radius: Option<f64>) {
    let lo = [0, 1, 2].map(|k| positions.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min) - 1.0);
    let hi = [0, 1, 2].map(|k| {
        positions
            .iter()
            .map(|p| p[k])
            .fold(f64::NEG_INFINITY, f64::max)
            + 1.0
    });
    let mut t = format!(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{}\nITEM: BOX BOUNDS ff ff ff\n",
        positions.len()
    );
    for k in 0..3 {
        t += &format!("{:.17e} {:.17e}\n", lo[k], hi[k]);
    }
    t += match radius {
        Some(_) => "ITEM: ATOMS id type x y z radius\n",
        None => "ITEM: ATOMS id type x y z\n",
    };
    for (i, p) in positions.iter().enumerate() {
        t += &format!("{} 1 {:.17e} {:.17e} {:.17e}", i + 1, p[0], p[1], p[2]);
        if let Some(r) = radius {
            t += &format!(" {r:e}");
        }
        t += "\n";
    }
    std::fs::write(path, t).unwrap();
}

/// Data of awkward shapes: particles piled on one spot are framed as one sphere (the
/// fit left every one out as far from a bulk of no extent, and the image was empty);
/// millimetre grains at UTM coordinates, which single precision cannot place, are said
/// to be so when nothing draws (the note blamed view options never given), and `info`
/// prints their extent with the digits that tell its ends apart; lengths of 10⁻²⁰ are
/// noted as below what the renderer resolves; a line of particles is called a line.
#[test]
fn data_of_awkward_shapes_is_framed_and_described() {
    let dir = tempfile::tempdir().unwrap();
    let size = ["--width", "32", "--height", "24"];
    // 50 particles at one spot.
    let pile = dir.path().join("pile.dump");
    awkward_dump(&pile, &[[1.0, 2.0, 3.0]; 50], None);
    let f = dir.path().join("pile.mdlod");
    ok(&["convert", s(&pile), "-o", s(&f)]);
    let png = dir.path().join("pile.png");
    let out = ok(&[&["render", s(&f), "-o", s(&png)][..], &size].concat());
    assert!(!out.contains("far from the rest"), "{out}");
    let (_, _, rgba) = read_png(&png);
    let drawn = rgba.chunks(4).filter(|p| p[..3] != [255, 255, 255]).count();
    // The one sphere fills a good part of the image, as a single particle's does.
    assert!(drawn > 100, "{drawn} pixels drawn");
    // Grains of 1 mm at UTM coordinates.
    let utm: Vec<[f64; 3]> = (0..27)
        .map(|i| {
            let g = [i % 3, i / 3 % 3, i / 9].map(|v| f64::from(v) * 0.002);
            [512345.678 + g[0], 4123456.789 + g[1], 123.456 + g[2]]
        })
        .collect();
    let dump = dir.path().join("utm.dump");
    awkward_dump(&dump, &utm, Some(0.0005));
    let f = dir.path().join("utm.mdlod");
    ok(&["convert", s(&dump), "-o", s(&f)]);
    let out = ok(&[&["render", s(&f), "-o", s(&png)][..], &size].concat());
    assert!(
        out.contains(
            "finer than single precision (in which the view is worked out) resolves there"
        ),
        "{out}"
    );
    assert!(!out.contains("--target, --zoom or view file"), "{out}");
    let info = ok(&["info", s(&f)]);
    let extent = info.lines().find(|l| l.contains("extent")).unwrap();
    assert!(
        extent.contains("512345.") && extent.contains("4123456.8"),
        "{extent}"
    );
    // Lengths of 10⁻²⁰.
    let tiny: Vec<[f64; 3]> = (0..27)
        .map(|i| [i % 3, i / 3 % 3, i / 9].map(|v| f64::from(v) * 1e-20))
        .collect();
    let dump = dir.path().join("tiny.dump");
    awkward_dump(&dump, &tiny, Some(4e-21));
    let out = ok(&["convert", s(&dump), "-o", s(&dir.path().join("tiny.mdlod"))]);
    assert!(out.contains("lengths this small"), "{out}");
    // A lattice of spacing 1 and three atoms lost far outside its box: the spacing is
    // the lattice's (the lost atoms' bounds made it 53, and the note called the atoms
    // scattered dots).
    let mut text = String::from(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n8003\nITEM: BOX BOUNDS pp pp pp\n\
         -0.5 19.5\n-0.5 19.5\n-0.5 19.5\nITEM: ATOMS id type x y z\n",
    );
    for i in 0..8000 {
        text += &format!("{} 1 {} {} {}\n", i + 1, i % 20, i / 20 % 20, i / 400);
    }
    for (i, z) in [(8001, 3000), (8002, 2500), (8003, -900)] {
        text += &format!("{i} 1 10 10 {z}\n");
    }
    let dump = dir.path().join("lost.dump");
    std::fs::write(&dump, text).unwrap();
    let out = ok(&["convert", s(&dump), "-o", s(&dir.path().join("lost.mdlod"))]);
    assert!(
        out.contains("3 particles lie more than 10 box lengths outside"),
        "{out}"
    );
    assert!(!out.contains("scattered dots"), "{out}");
    // A line of particles along x, far longer than the image is wide: its spheres miss
    // every pixel centre, which is said.
    let line: Vec<[f64; 3]> = (0..400).map(|i| [f64::from(i), 0.0, 0.0]).collect();
    let dump = dir.path().join("line.dump");
    awkward_dump(&dump, &line, None);
    let f = dir.path().join("line.mdlod");
    ok(&["convert", s(&dump), "-o", s(&f)]);
    let info = ok(&["info", s(&f)]);
    assert!(
        info.contains("every particle's centre on one line"),
        "{info}"
    );
    let out = ok(&[&["render", s(&f), "-o", s(&png)][..], &size].concat());
    assert!(
        out.contains("nothing shows: the spheres drawn are at most"),
        "{out}"
    );
    let (_, _, rgba) = read_png(&png);
    assert!(rgba.chunks(4).all(|p| p[..3] == [255, 255, 255]));
}

/// `info` counts each species over the whole SPECIES section: a flipped byte there is
/// refused by the section's checksum (it printed wrong counts, with success).
#[test]
fn info_refuses_a_species_section_that_fails_its_checksum() {
    let dir = tempfile::tempdir().unwrap();
    let input = lammps_sample_path("cuag_alloy.unwrapped.dump");
    let file = dir.path().join("a.mdlod");
    ok(&["convert", s(&input), "-o", s(&file)]);
    ok(&["info", s(&file)]);
    let at = {
        let f = MdlodFile::open(&file).unwrap();
        let species = mdlod_format::layout::SectionKind::Species as u32;
        let entry = f.sections().iter().find(|e| e.kind == species).unwrap();
        (entry.offset + entry.length / 2) as usize
    };
    let mut bytes = std::fs::read(&file).unwrap();
    bytes[at] ^= 1;
    std::fs::write(&file, bytes).unwrap();
    let err = fails(&["info", s(&file)]);
    assert!(
        err.contains("SPECIES") && err.contains("checksum mismatch"),
        "{err}"
    );
}

/// `convert` records its input as `batch` does: a `%` piece set's pieces, and a raw
/// sidecar with the arrays it names (it recorded a piece set of size 0, and the sidecar
/// alone, whose size does not change with new arrays behind it).
#[test]
fn convert_records_every_file_of_its_input() {
    let dir = tempfile::tempdir().unwrap();
    let source = |f: &Path| {
        let v: serde_json::Value = serde_json::from_str(&ok(&["info", s(f), "--json"])).unwrap();
        v["source"]["size"].as_u64().unwrap()
    };
    let size = |p: &Path| std::fs::metadata(p).unwrap().len();
    let lammps = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/lammps");
    let pieces = lammps.join("cu_melt_mpi.%.dump");
    let out = dir.path().join("pieces.mdlod");
    ok(&["convert", s(&pieces), "-o", s(&out)]);
    let whole = size(&lammps.join("cu_melt_mpi.0.dump")) + size(&lammps.join("cu_melt_mpi.1.dump"));
    assert_eq!(source(&out), whole);
    let sidecar = dir.path().join("small.raw.json");
    generate(&["alloy", "-n", "2000", "--format", "raw"], &sidecar);
    let out = dir.path().join("raw.mdlod");
    ok(&["convert", s(&sidecar), "-o", s(&out)]);
    let files: u64 = std::fs::read_dir(dir.path())
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .unwrap()
                .to_str()
                .unwrap()
                .starts_with("small.")
        })
        .map(|p| size(&p))
        .sum();
    assert!(files > size(&sidecar));
    assert_eq!(source(&out), files);
}

/// The options that change what is read from the input are recorded in the file
/// (`input_options`), shown by `info` and its JSON: a wrapped or renamed conversion is
/// told from a plain one of the same dump.
#[test]
fn the_options_that_changed_the_data_are_recorded() {
    let dir = tempfile::tempdir().unwrap();
    let input = lammps_sample_path("cuag_alloy.unwrapped.dump");
    let plain = dir.path().join("plain.mdlod");
    ok(&["convert", s(&input), "-o", s(&plain)]);
    let changed = dir.path().join("changed.mdlod");
    ok(&[
        "convert",
        s(&input),
        "-o",
        s(&changed),
        "--wrap",
        "--species-name",
        "Ag=Au",
    ]);
    let options = |f: &Path| {
        let v: serde_json::Value = serde_json::from_str(&ok(&["info", s(f), "--json"])).unwrap();
        v["input_options"].clone()
    };
    assert_eq!(options(&plain), serde_json::json!([]));
    assert_eq!(
        options(&changed),
        serde_json::json!(["--wrap", "--species-name Ag=Au"])
    );
    let info = ok(&["info", s(&changed)]);
    assert!(
        info.contains("read with    --wrap --species-name Ag=Au"),
        "{info}"
    );
    assert!(!ok(&["info", s(&plain)]).contains("read with"));
}

/// A slab that keeps particles of hidden species only draws nothing: the note says so,
/// not only that the planes may point the wrong way.
#[test]
fn a_slab_of_hidden_species_says_what_hides_it() {
    let dir = tempfile::tempdir().unwrap();
    let mut text = String::from("128\nProperties=species:S:1:pos:R:3\n");
    for i in 0..64 {
        let (y, z) = (f64::from(i % 8), f64::from(i / 8));
        text += &format!("Cu {} {y} {z}\nAg {} {y} {z}\n", i % 4, 10 + i % 4);
    }
    let xyz = dir.path().join("two.xyz");
    std::fs::write(&xyz, text).unwrap();
    let f = dir.path().join("two.mdlod");
    ok(&["convert", s(&xyz), "-o", s(&f)]);
    let png = dir.path().join("slab.png");
    let out = ok(&[
        "render",
        s(&f),
        "-o",
        s(&png),
        "--width",
        "32",
        "--height",
        "24",
        "--clip",
        "1,0,0,4",
        "--hide-species",
        "Cu",
    ]);
    assert!(
        out.contains("nothing is drawn: the --clip planes keep no particle that is not hidden"),
        "{out}"
    );
}

/// `--palette okabe-ito` draws the palette's species in Okabe and Ito's colours, told
/// apart with the common colour-vision deficiencies (the default's first two, orange
/// and blue-violet, were close in grey print), keyed so; a colour given still wins, and
/// beside a colour map, which replaces species colours, it is refused.
#[test]
fn the_okabe_ito_palette_colours_the_palette_species_and_their_key() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("a.lammpstrj");
    generate(&["alloy", "-n", "3000"], &dump);
    let file = dir.path().join("a.mdlod");
    ok(&["convert", s(&dump), "-o", s(&file), "--attribute", "c_pe"]);
    let (png, svg) = (dir.path().join("a.png"), dir.path().join("a.svg"));
    let base = ["render", s(&file), "-o", s(&png), "--width", "64"];
    let args = [&base[..], &["--height", "48", "--legend", s(&svg)]].concat();
    ok(&[&args[..], &["--palette", "okabe-ito"]].concat());
    let key = std::fs::read_to_string(&svg).unwrap().to_lowercase();
    assert!(key.contains("#e69f00") && key.contains("#0072b2"), "{key}");
    // The pixels drawn: orange's hue (green over red 0.69 in sRGB) where the file's
    // #e66633 has 0.44.
    let orange = |png: &Path| {
        read_png(png)
            .2
            .chunks_exact(4)
            .filter(|p| {
                let (r, g, b) = (f32::from(p[0]), f32::from(p[1]), f32::from(p[2]));
                p[3] == 255 && r > 60.0 && g / r > 0.58 && g / r < 0.8 && b < 0.3 * r
            })
            .count()
    };
    let given = orange(&png);
    ok(&args);
    let own = orange(&png);
    assert!(
        given > 200 && own < given / 10,
        "{given} against {own} orange pixels"
    );
    ok(&[
        &args[..],
        &["--palette", "okabe-ito", "--species-colour", "1=#00ff00"],
    ]
    .concat());
    let key = std::fs::read_to_string(&svg).unwrap().to_lowercase();
    assert!(
        key.contains("#00ff00") && key.contains("#0072b2") && !key.contains("#e69f00"),
        "{key}"
    );
    // Splats and the iso-surface draw it too (their packing kept the file's colours
    // while the key showed the palette's).
    for mode in ["splat-over", "iso"] {
        let mode_args = [&args[..], &["--mode", mode]].concat();
        ok(&mode_args);
        let own = std::fs::read(&png).unwrap();
        ok(&[&mode_args[..], &["--palette", "okabe-ito"]].concat());
        assert_ne!(std::fs::read(&png).unwrap(), own, "{mode}");
    }
    let e = fails(
        &[
            &args[..],
            &["--palette", "okabe-ito", "--colour-map", "viridis"],
        ]
        .concat(),
    );
    assert!(
        e.contains("--palette has no effect with --colour-map"),
        "{e}"
    );
}

/// In a Slurm job array's task, `--shard none` converts every frame into dataset.json
/// (an array of one task wrote a shard's manifest, which render refused until merged,
/// and no option gave a whole run); the array's own shard names the merge.
#[test]
fn shard_none_makes_a_whole_run_inside_a_job_array() {
    let dir = tempfile::tempdir().unwrap();
    let dump = lammps_sample_path("cu_melt.custom.dump");
    let run = |d: &Path, extra: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_mdlod"))
            .args([&["batch", s(&dump), "-o", s(d)][..], extra].concat())
            .env("SLURM_ARRAY_TASK_ID", "0")
            .env("SLURM_ARRAY_TASK_COUNT", "1")
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8(out.stdout).unwrap()
    };
    let (arrayed, whole) = (dir.path().join("a"), dir.path().join("w"));
    let said = run(&arrayed, &[]);
    assert!(arrayed.join("dataset.shard-0-of-1.json").exists());
    assert!(
        said.contains("from the Slurm job array's variables") && said.contains("--merge"),
        "{said}"
    );
    run(&whole, &["--shard", "none"]);
    assert!(whole.join("dataset.json").exists());
    assert!(!whole.join("dataset.shard-0-of-1.json").exists());
}

/// `--dpi` records the resolution in every PNG written (a still, a turntable's views)
/// as pixels per metre, for a journal's figure check; the pixels are those without it.
#[test]
fn dpi_is_recorded_in_every_png_and_changes_no_pixel() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("a.lammpstrj");
    generate(&["alloy", "-n", "2000"], &dump);
    let file = dir.path().join("a.mdlod");
    ok(&["convert", s(&dump), "-o", s(&file)]);
    let phys = |p: &Path| {
        let png = std::fs::read(p).unwrap();
        png.windows(4).position(|w| w == b"pHYs").map(|at| {
            let at = at + 4;
            let word = |k: usize| u32::from_be_bytes(png[at + k..at + k + 4].try_into().unwrap());
            (word(0), word(4), png[at + 8])
        })
    };
    let (plain, print) = (dir.path().join("plain.png"), dir.path().join("print.png"));
    let base = ["render", s(&file), "--width", "48", "--height", "32"];
    ok(&[&base[..], &["-o", s(&plain)]].concat());
    ok(&[&base[..], &["-o", s(&print), "--dpi", "300"]].concat());
    assert_eq!(phys(&plain), None);
    assert_eq!(phys(&print), Some((11811, 11811, 1)));
    assert_eq!(read_png(&plain).2, read_png(&print).2);
    let turn = dir.path().join("t-%d.png");
    ok(&[
        &base[..],
        &["-o", s(&turn), "--turntable", "2", "--dpi", "600"],
    ]
    .concat());
    for i in 0..2 {
        assert_eq!(
            phys(&dir.path().join(format!("t-{i}.png"))),
            Some((23622, 23622, 1))
        );
    }
    let e = fails(&[&base[..], &["-o", s(&print), "--dpi", "0"]].concat());
    assert!(e.contains("above 0"), "{e}");
}
