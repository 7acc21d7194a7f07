//! `mdlod view` in a real window under Xvfb (with lavapipe in CI): a scripted session
//! opens a batch data set, orbits, switches to S-NDFs, moves the light, steps a timestep
//! and takes screenshots; the screenshots are checked against what the action implies and
//! against `mdlod render` and `mdlod shade` of the same view and S-NDFs.
//!
//! Needs `Xvfb` (scripts/setup.sh installs it). Without it the test fails, unless
//! `MDLOD_SKIP_WINDOW_TESTS=1` says to leave it out.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

fn mdlod(args: &[&str], env: &[(&str, &str)]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_mdlod"))
        .args(args)
        .envs(env.iter().copied())
        .output()
        .expect("the mdlod binary runs");
    assert!(
        out.status.success(),
        "mdlod {args:?} failed: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// A private X server, killed on drop.
struct Xvfb {
    child: Child,
    display: String,
}

impl Drop for Xvfb {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn xvfb() -> Option<Xvfb> {
    if std::env::var("MDLOD_SKIP_WINDOW_TESTS").is_ok_and(|v| v == "1") {
        eprintln!("MDLOD_SKIP_WINDOW_TESTS=1: the window test is left out");
        return None;
    }
    let first = 100 + std::process::id() % 400;
    for n in first..first + 50 {
        if Path::new(&format!("/tmp/.X{n}-lock")).exists() {
            continue;
        }
        let child = Command::new("Xvfb")
            .args([
                &format!(":{n}"),
                "-screen",
                "0",
                "1024x768x24",
                "-nolisten",
                "tcp",
            ])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn();
        let mut child = match child {
            Ok(c) => c,
            Err(e) => panic!(
                "Xvfb could not start ({e}): install it (scripts/setup.sh does), or set \
                 MDLOD_SKIP_WINDOW_TESTS=1 to leave the window test out"
            ),
        };
        let socket = PathBuf::from(format!("/tmp/.X11-unix/X{n}"));
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(15) {
            // Ready once it accepts connections.
            if std::os::unix::net::UnixStream::connect(&socket).is_ok() {
                return Some(Xvfb {
                    child,
                    display: format!(":{n}"),
                });
            }
            if let Ok(Some(_)) = child.try_wait() {
                break; // Display taken: try the next.
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        let _ = child.kill();
        let _ = child.wait();
    }
    panic!("no X display could be started with Xvfb");
}

struct Png {
    w: u32,
    h: u32,
    rgba: Vec<u8>,
}

fn png(path: &Path) -> Png {
    let decoder = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    ));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgba);
    buf.truncate(info.buffer_size());
    Png {
        w: info.width,
        h: info.height,
        rgba: buf,
    }
}

/// Share of pixels whose largest channel difference exceeds `tol` levels.
fn differing(a: &Png, b: &Png, tol: u8) -> f64 {
    assert_eq!((a.w, a.h), (b.w, b.h));
    let n = a
        .rgba
        .chunks_exact(4)
        .zip(b.rgba.chunks_exact(4))
        .filter(|(p, q)| (0..3).any(|k| p[k].abs_diff(q[k]) > tol))
        .count();
    n as f64 / f64::from(a.w * a.h)
}

#[test]
fn a_scripted_session_orbits_relights_steps_and_screenshots() {
    let Some(x) = xvfb() else { return };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let p = |name: &str| d.join(name).to_str().unwrap().to_string();
    mdlod(
        &[
            "generate",
            "alloy",
            "-n",
            "6000",
            "--frames",
            "2",
            "-o",
            &p("a.lammpstrj"),
        ],
        &[],
    );
    mdlod(&["batch", &p("a.lammpstrj"), "-o", &p("runs")], &[]);
    let script = serde_json::json!([
        {"action": "screenshot", "path": p("start.png")},
        {"action": "orbit", "dx": 150, "dy": 0},
        {"action": "screenshot", "path": p("orbited.png")},
        {"action": "save_view", "path": p("view.json")},
        {"action": "mode", "mode": "sndf"},
        {"action": "sndf_iterations", "n": 16},
        {"action": "screenshot", "path": p("sndf.png")},
        {"action": "save_sndf", "path": p("view.sndf")},
        {"action": "light", "index": 0, "direction": [1, 0, 0.3]},
        {"action": "screenshot", "path": p("relit.png")},
        {"action": "paint", "x": 0.0, "y": 0.0, "radius": 0.7, "colour": [0.0, 1.0, 0.0]},
        {"action": "screenshot", "path": p("painted.png")},
        {"action": "clear_paint"},
        {"action": "mode", "mode": "standard"},
        // Back to `mdlod render`'s light (it has one, fixed).
        {"action": "light", "index": 0, "direction": [-0.35, 0.45, 1.0]},
        {"action": "step", "delta": 1},
        {"action": "screenshot", "path": p("stepped.png")},
        {"action": "screenshot", "path": p("big.png"), "width": 96, "height": 64},
        {"action": "species_visible", "name": "2", "visible": false},
        {"action": "screenshot", "path": p("hidden.png")}
    ]);
    std::fs::write(d.join("session.json"), script.to_string()).unwrap();
    let xdg = d.join("xdg");
    std::fs::create_dir(&xdg).unwrap();
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&xdg, std::fs::Permissions::from_mode(0o700)).unwrap();
    }
    let env = [
        ("DISPLAY", x.display.as_str()),
        ("XDG_RUNTIME_DIR", xdg.to_str().unwrap()),
        ("WAYLAND_DISPLAY", ""),
    ];
    let (w, h) = ("160", "120");
    mdlod(
        &[
            "view",
            &p("runs"),
            "--width",
            w,
            "--height",
            h,
            "--script",
            &p("session.json"),
            "--script-timeout",
            "300",
        ],
        &env,
    );
    // Back to the standard mode while S-NDFs refine (far more rays than the session
    // lasts): the standard image stays and settles; no S-NDF batch replaces it.
    std::fs::write(
        d.join("mode-switch.json"),
        serde_json::json!([
            {"action": "mode", "mode": "sndf"},
            {"action": "sndf_iterations", "n": 4096},
            {"action": "pause", "seconds": 0.5},
            {"action": "mode", "mode": "standard"},
            {"action": "wait_still"},
            {"action": "pause", "seconds": 1},
            {"action": "screenshot", "path": p("switched.png")}
        ])
        .to_string(),
    )
    .unwrap();
    mdlod(
        &[
            "view",
            &p("runs"),
            "--view",
            &p("view.json"),
            "--width",
            w,
            "--height",
            h,
            "--script",
            &p("mode-switch.json"),
            "--script-timeout",
            "60",
        ],
        &env,
    );
    // An error in a script ends it at once and fails the command, naming the cause.
    let bad = d.join("bad-session.json");
    std::fs::write(
        &bad,
        serde_json::json!([
            {"action": "load_view", "path": p("missing-view.json")},
            {"action": "wait_still"},
            {"action": "pause", "seconds": 600}
        ])
        .to_string(),
    )
    .unwrap();
    let t0 = Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_mdlod"))
        .args([
            "view",
            &p("runs"),
            "--width",
            "64",
            "--height",
            "48",
            "--script",
        ])
        .arg(&bad)
        .envs(env.iter().copied())
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    // (Named by the action that read it.)
    assert!(
        err.contains("script action 0 (load_view): ") && err.contains("missing-view.json"),
        "{err}"
    );
    assert!(
        t0.elapsed() < Duration::from_secs(120),
        "the failed script did not end"
    );
    // A script that runs past its time limit fails the command too.
    let slow = d.join("slow-session.json");
    std::fs::write(
        &slow,
        serde_json::json!([{"action": "pause", "seconds": 600}]).to_string(),
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_mdlod"))
        .args(["view", &p("runs"), "--width", "64", "--height", "48"])
        .args(["--script-timeout", "2", "--script"])
        .arg(&slow)
        .envs(env.iter().copied())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success()
            && err.contains("script action 0 (pause): the script ran past its --script-timeout"),
        "{err}"
    );
    drop(x);

    let start = png(&d.join("start.png"));
    let orbited = png(&d.join("orbited.png"));
    assert_eq!(
        (start.w, start.h),
        (160, 120),
        "the image fills the window's view area"
    );
    // Orbiting turned the data: much of the picture changed.
    assert!(differing(&start, &orbited, 8) > 0.05);
    // The window shows what `mdlod render` gives for the saved view.
    let view = p("view.json");
    let render = |frame: &str, out: &str, extra: &[&str]| {
        let mut args = vec![
            "render", frame, "-o", out, "--view", &view, "--width", w, "--height", h,
        ];
        args.extend_from_slice(extra);
        mdlod(&args, &[]);
        png(Path::new(out))
    };
    let frame0 = p("runs/frame-0.mdlod");
    let frame1 = p("runs/frame-100.mdlod");
    let headless = render(&frame0, &p("headless.png"), &[]);
    assert!(differing(&orbited, &headless, 2) < 0.002);
    assert!(differing(&png(&d.join("switched.png")), &headless, 2) < 0.002);
    // S-NDFs refined to 16 rays in the viewer's batches look like `render --mode sndf`.
    let sndf = png(&d.join("sndf.png"));
    let sndf_headless = render(
        &frame0,
        &p("sndf-headless.png"),
        &["--mode", "sndf", "--iterations", "16"],
    );
    assert!(differing(&sndf, &sndf_headless, 3) < 0.01);
    // Moving the light re-lit the picture, exactly as `mdlod shade` lights the S-NDFs the
    // viewer saved.
    let relit = png(&d.join("relit.png"));
    assert!(differing(&sndf, &relit, 8) > 0.05);
    mdlod(
        &[
            "shade",
            &p("view.sndf"),
            "-o",
            &p("shaded.png"),
            "--light",
            "1,0,0.3",
        ],
        &[],
    );
    assert!(differing(&relit, &png(&d.join("shaded.png")), 1) < 0.001);
    // Painting the normal disk green re-colours the S-NDFs: green where it was not.
    let painted = png(&d.join("painted.png"));
    let green = |img: &Png| {
        img.rgba
            .chunks_exact(4)
            .filter(|p| p[1] > p[0].saturating_add(60) && p[1] > p[2].saturating_add(60))
            .count()
    };
    assert!(
        green(&painted) > 20 * green(&relit).max(1),
        "{} green pixels",
        green(&painted)
    );
    // The next timestep is another picture: that frame's, from the same view.
    let stepped = png(&d.join("stepped.png"));
    assert!(differing(&stepped, &orbited, 8) > 0.01);
    let headless1 = render(&frame1, &p("headless1.png"), &[]);
    assert!(differing(&stepped, &headless1, 2) < 0.002);
    // A screenshot at another size through the headless path.
    let big = png(&d.join("big.png"));
    let out = p("big-headless.png");
    mdlod(
        &[
            "render", &frame1, "-o", &out, "--view", &view, "--width", "96", "--height", "64",
        ],
        &[],
    );
    assert!(differing(&big, &png(Path::new(&out)), 2) < 0.002);
    // Hiding species 2 in the window is `render --hide-species 2`.
    let hidden = png(&d.join("hidden.png"));
    assert!(differing(&hidden, &stepped, 8) > 0.01);
    let headless_hidden = render(&frame1, &p("hidden-headless.png"), &["--hide-species", "2"]);
    assert!(differing(&hidden, &headless_hidden, 2) < 0.002);
}

#[test]
fn a_bad_script_is_refused_before_the_window_opens() {
    let dir = tempfile::tempdir().unwrap();
    let script = dir.path().join("bad.json");
    std::fs::write(&script, r#"[{"action": "fly"}]"#).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_mdlod"))
        .args([
            "view",
            "missing.mdlod",
            "--script",
            script.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.json") && err.contains("fly"), "{err}");
    let f = dir.path().join("t.mdlod");
    std::fs::write(&f, b"not an mdlod file").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_mdlod"))
        .args(["view", f.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("t.mdlod") && !err.contains("panicked"),
        "{err}"
    );
}
