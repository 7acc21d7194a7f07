//! Benchmarks of the renderer core: frame time and spheres drawn versus data size, with
//! and without level of detail; the first-image latency of a freshly opened file through
//! the streaming pool; resident host memory. `cargo bench --bench render` prints the
//! table and rewrites the renderer section of BENCHMARKS.md (or of the file named by
//! `MDLOD_BENCH_OUT`).
//!
//! `MDLOD_RENDER_SIZES` (default `1000000,10000000,100000000` for the main table,
//! `1000000,10000000` for the others): crater data sets generated and converted into
//! `data/bench/` when missing (text dumps up to 2×10^7 particles, raw arrays above,
//! converted within 4 GiB). `MDLOD_RENDER_FULL_MAX` (default 100000000): the largest
//! size also drawn without level of detail (every particle, in batches where the cut is
//! larger than one storage binding): its GPU time, summed over the batches, and the
//! whole frame's wall time (traversal, packing, upload, drawing, read-back).
//! `MDLOD_RENDER_ERROR` (default 1) and `MDLOD_RENDER_BUDGET` (default 4000000): the
//! screen error in pixels and the sphere budget of the level-of-detail frames.
//! `MDLOD_RENDER_COMPARE_MAX` (default 20000000): the largest size also drawn without
//! occlusion culling, for comparison. `MDLOD_RENDER_ONLY=errors` compares the first and
//! the last size over the screen errors `MDLOD_RENDER_ERRORS` (default `1,2,4,8,16`).

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use mdlod_datasets::{write_lammps_dump_to_path, write_raw_arrays, GenerateOptions, Kind};
use mdlod_format::MdlodFile;
use mdlod_preprocess::convert::{convert_file, ConvertOptions, FrameSelect};
use mdlod_preprocess::readers::ReadOptions;
use mdlod_preprocess::NoProgress;
use mdlod_render::{
    render_image, render_streaming, GpuContext, Projection, RenderOptions, Renderer, ViewSpec,
};

const W: u32 = 1280;
const H: u32 = 720;

fn env_list(name: &str, default: &str) -> Vec<u64> {
    std::env::var(name)
        .unwrap_or_else(|_| default.into())
        .split(',')
        .filter_map(|s| s.trim().parse::<f64>().ok().map(|v| v as u64))
        .collect()
}

/// Sizes above this are generated as raw arrays rather than as text dumps.
const LARGE: u64 = 20_000_000;

/// The converted crater of `n` particles in `data/bench/`, generated and converted when
/// missing.
fn dataset(n: u64) -> PathBuf {
    let mdlod = PathBuf::from(format!("data/bench/crater-{n}.mdlod"));
    if mdlod.exists() {
        return mdlod;
    }
    std::fs::create_dir_all("data/bench").unwrap();
    let mut opts = ConvertOptions {
        radii: vec![("1".into(), 1.28)],
        ..Default::default()
    };
    let (source, raw_dir) = if n > LARGE {
        // Raw arrays (the values the text dump would hold, without its text), converted
        // out of core within 4 GiB as `benches/out_of_core.sh` does, then removed.
        let dir = PathBuf::from("data/bench/raw");
        // A fresh clone has no such directory yet.
        std::fs::create_dir_all(&dir).unwrap();
        eprintln!(
            "generating {n} particles as raw arrays in {}",
            dir.display()
        );
        let gen = GenerateOptions::new(Kind::Crater, n);
        let (sidecar, _) = write_raw_arrays(&gen, &dir, &format!("crater-{n}"), |_| {}).unwrap();
        opts.chunks.memory_limit = 4 << 30;
        (sidecar, Some(dir))
    } else {
        let dump = PathBuf::from(format!("data/bench/crater-{n}.lammpstrj"));
        if !dump.exists() {
            eprintln!("generating {}", dump.display());
            write_lammps_dump_to_path(&GenerateOptions::new(Kind::Crater, n), &dump, |_| {})
                .unwrap();
        }
        (dump, None)
    };
    eprintln!("converting {}", source.display());
    convert_file(
        &source,
        &mdlod,
        FrameSelect::Last,
        &ReadOptions::default(),
        &opts,
        &NoProgress,
    )
    .unwrap();
    if let Some(dir) = raw_dir {
        std::fs::remove_dir_all(dir).unwrap();
    }
    mdlod
}

/// [`dataset`]`(n)` (of at most [`LARGE`] particles) with the crater's kinetic energy
/// kept as its attribute (`--attribute c_ke`), for the modes coloured by it; converted
/// from the same dump when missing.
fn dataset_with_ke(n: u64) -> PathBuf {
    let mdlod = PathBuf::from(format!("data/bench/crater-{n}-c_ke.mdlod"));
    if mdlod.exists() {
        return mdlod;
    }
    assert!(n <= LARGE, "the kinetic energy is kept for text dumps only");
    dataset(n);
    let dump = PathBuf::from(format!("data/bench/crater-{n}.lammpstrj"));
    if !dump.exists() {
        write_lammps_dump_to_path(&GenerateOptions::new(Kind::Crater, n), &dump, |_| {}).unwrap();
    }
    eprintln!("converting {} with c_ke", dump.display());
    convert_file(
        &dump,
        &mdlod,
        FrameSelect::Last,
        &ReadOptions {
            attribute: Some("c_ke".into()),
            ..Default::default()
        },
        &ConvertOptions {
            radii: vec![("1".into(), 1.28)],
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
    mdlod
}

/// The begin and end markers of a generated section: `MDLOD_BENCH_SECTION` (default
/// `render`; another name for results from another adapter) followed by `suffix`.
fn markers(suffix: &str) -> (String, String) {
    let section = std::env::var("MDLOD_BENCH_SECTION").unwrap_or_else(|_| "render".into()) + suffix;
    (
        format!("<!-- {section}:begin"),
        format!("<!-- {section}:end -->\n"),
    )
}

/// Prints a generated section `t` (from `begin` through `end`) and writes it into
/// BENCHMARKS.md (or the file `MDLOD_BENCH_OUT` names) in place of the old one, or at
/// the end under `heading`.
fn write_section(begin: &str, end: &str, t: &str, heading: &str) {
    println!("{t}");
    let out = std::env::var("MDLOD_BENCH_OUT").unwrap_or_else(|_| "BENCHMARKS.md".into());
    let old = std::fs::read_to_string(&out).unwrap_or_else(|_| "# Benchmarks\n\n".into());
    let new = match (old.find(begin), old.find(end)) {
        (Some(a), Some(b)) => format!("{}{}{}", &old[..a], t, &old[b + end.len()..]),
        _ => format!("{old}\n{heading}\n\n{t}"),
    };
    std::fs::write(&out, new).unwrap();
    eprintln!("updated {out}");
}

fn rss_mib() -> f64 {
    status_mib("VmRSS:")
}

/// A memory line of `/proc/self/status` (`VmRSS:`, `RssAnon:`, `RssFile:`), in MiB.
fn status_mib(key: &str) -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with(key))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(0.0, |kb| kb / 1024.0)
}

fn median(mut v: Vec<Duration>) -> Duration {
    v.sort();
    v[v.len() / 2]
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn main() {
    let sizes = env_list("MDLOD_RENDER_SIZES", "1000000,10000000");
    let full_max = env_list("MDLOD_RENDER_FULL_MAX", "100000000")[0];
    let error_px: f32 = std::env::var("MDLOD_RENDER_ERROR")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1.0);
    let budget = env_list("MDLOD_RENDER_BUDGET", "4000000")[0];
    let compare_max = env_list("MDLOD_RENDER_COMPARE_MAX", "20000000")[0];
    let renderer = Renderer::new(GpuContext::new().expect("a GPU adapter"));
    let adapter = renderer.ctx.adapter_name().to_string();
    if std::env::var("MDLOD_RENDER_ONLY").is_ok_and(|v| v == "splat") {
        splat_table(&renderer, &adapter, sizes[0]);
        return;
    }
    if std::env::var("MDLOD_RENDER_ONLY").is_ok_and(|v| v == "sndf") {
        sndf_table(&renderer, &adapter, sizes[0]);
        sndf_wide_table(&renderer, &adapter, sizes[0]);
        smip_table(&renderer, &adapter, sizes[0]);
        return;
    }
    if std::env::var("MDLOD_RENDER_ONLY").is_ok_and(|v| v == "sndf-wide") {
        sndf_wide_table(&renderer, &adapter, sizes[0]);
        return;
    }
    if std::env::var("MDLOD_RENDER_ONLY").is_ok_and(|v| v == "smip") {
        smip_table(&renderer, &adapter, sizes[0]);
        return;
    }
    if std::env::var("MDLOD_RENDER_ONLY").is_ok_and(|v| v == "density") {
        density_table(&renderer, &adapter, &sizes);
        return;
    }
    if std::env::var("MDLOD_RENDER_ONLY").is_ok_and(|v| v == "viewer") {
        viewer_table(&renderer, &adapter, &sizes);
        return;
    }
    if std::env::var("MDLOD_RENDER_ONLY").is_ok_and(|v| v == "errors") {
        errors_table(&renderer, &adapter, &sizes);
        return;
    }
    // The main table spans 10^6 to 10^8 particles unless told otherwise.
    let sizes = match std::env::var_os("MDLOD_RENDER_SIZES") {
        Some(_) => sizes,
        None => vec![1_000_000, 10_000_000, 100_000_000],
    };
    let view = ViewSpec::Orbit {
        azimuth_deg: 30.0,
        elevation_deg: 25.0,
        zoom: 1.0,
        projection: Projection::Perspective,
    };
    let base = RenderOptions {
        width: W,
        height: H,
        view,
        spp: 1,
        error_px,
        budget,
        ..Default::default()
    };
    let pool: u64 = 512 << 20;
    let mut rows = vec![];
    let mut costs = vec![];
    for &n in &sizes {
        let path = dataset(n);
        let size_mb = std::fs::metadata(&path).unwrap().len() as f64 / 1e6;
        // First image: open the file and draw what the streaming pool holds after one
        // frame (the coarse levels), then until the view is complete.
        let t = Instant::now();
        let file = Arc::new(MdlodFile::open(&path).unwrap());
        let open = t.elapsed();
        let (_img, stream) = render_streaming(&renderer, file.clone(), &base, pool).unwrap();
        let first = open + stream.first_frame_time.unwrap_or_default();
        let complete = open + stream.total_time;
        let rss_after_stream = rss_mib();
        let reps = if n >= 50_000_000 { 3 } else { 5 };
        // Level of detail with occlusion culling (the default), then without it.
        let lod = |opts: &RenderOptions, reps: usize| {
            let mut gpu = vec![];
            let mut cost = vec![];
            let mut report = None;
            for _ in 0..reps {
                let (_img, r) = render_image(&renderer, &file, opts).unwrap();
                let g = r.gpu_time.unwrap_or(r.total_time);
                gpu.push(g);
                cost.push(g + r.traversal_time);
                report = Some(r);
            }
            (median(gpu), median(cost), report.unwrap())
        };
        let (gpu, cost, r) = lod(&base, reps);
        let plain = (n <= compare_max).then(|| {
            let opts = RenderOptions {
                occlusion: false,
                ..base.clone()
            };
            lod(&opts, reps.min(3))
        });
        let full = (n <= full_max).then(|| {
            let opts = RenderOptions {
                error_px: 0.0,
                budget: u64::MAX,
                occlusion: false,
                ..base.clone()
            };
            let (mut times, mut walls) = (vec![], vec![]);
            let mut drawn = 0;
            for _ in 0..reps.min(3) {
                let (_img, r) = render_image(&renderer, &file, &opts).unwrap();
                times.push(r.gpu_time.unwrap_or(r.total_time));
                walls.push(r.total_time);
                drawn = r.particles_drawn + r.nodes_drawn;
            }
            (median(times), drawn, median(walls))
        });
        let mib = |b: u64| b as f64 / f64::from(1u32 << 20);
        let row = format!(
            "| {n} | {size_mb:.0} | {} | {} | {:.2} | {:.1} | {:.1} | {:.1} | {} | {} | {:.0} | {:.0} | {} | {} | {:.0} | {:.0} / {:.0} |",
            r.particles_drawn + r.nodes_drawn,
            r.nodes_occluded,
            r.error_px,
            ms(gpu),
            ms(r.traversal_time),
            ms(cost),
            plain.as_ref().map_or("—".into(), |p| (p.2.particles_drawn + p.2.nodes_drawn).to_string()),
            plain.as_ref().map_or("—".into(), |p| format!("{:.1} / {:.1}", ms(p.0), ms(p.1))),
            ms(first),
            ms(complete),
            full.map_or("—".into(), |f| format!("{:.1} / {:.0}", ms(f.0), ms(f.2))),
            full.map_or("—".into(), |f| f.1.to_string()),
            rss_after_stream,
            mib(r.gpu_data_bytes),
            mib(stream.gpu_data_bytes + stream.gpu_target_bytes),
        );
        eprintln!("{row}");
        rows.push(row);
        costs.push((n, gpu, cost, r.error_px));
    }
    let (begin, end) = markers("");
    let ovito = ovito_side_by_side();
    let mut t = String::new();
    t.push_str(&format!(
        "{begin} (generated by `cargo bench --bench render`; do not edit) -->\n"
    ));
    t.push_str(&format!(
        "Adapter: **{adapter}**. Image {W}×{H}, 1 sample per pixel, perspective view fitting the whole crater data set, screen error {error_px} px, budget {budget} spheres. Frame times are GPU time (timestamp queries) when the adapter has them, else wall time; medians. Streaming pool {} MiB.\n\n",
        pool >> 20,
    ));
    t.push_str("| particles | .mdlod MB | spheres drawn | hidden clusters left out | achieved error px | GPU frame ms | traversal ms | frame cost ms (traversal + GPU) | spheres without occlusion culling | without: GPU ms / cost ms | first image ms (open + coarse frame) | view complete ms (streaming) | every particle: GPU ms / whole frame ms | spheres (every particle) | host RSS MiB | GPU MiB: cut / streaming pool + targets |\n");
    t.push_str(
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in &rows {
        t.push_str(r);
        t.push('\n');
    }
    if let (Some(small), Some(large)) = (costs.first(), costs.last()) {
        if large.0 > small.0 {
            t.push_str(&format!(
                "\nScaling from {} to {} particles at the same image size and error: GPU frame time {:.2}×, frame cost (traversal + GPU) {:.2}× (target ≤ 1.5×); achieved error {:.2} and {:.2} px.\n",
                small.0,
                large.0,
                large.1.as_secs_f64() / small.1.as_secs_f64(),
                large.2.as_secs_f64() / small.2.as_secs_f64(),
                small.3,
                large.3,
            ));
        }
    }
    if let Some(o) = ovito {
        t.push_str(&o);
    }
    t.push_str(&end);
    write_section(&begin, &end, &t, &format!("### Renderer core on {adapter}"));
}

/// The frame-cost comparison of the first and the last size over a range of screen
/// errors (`MDLOD_RENDER_ERRORS`, default `1,2,4,8,16`), no budget: where the finest
/// level is coarser than the error on both sizes, their cuts are both bounded by the
/// screen; where it is not, the larger data set draws the finer surface the error asks
/// for. Writes the `-errors` section.
fn errors_table(renderer: &Renderer, adapter: &str, sizes: &[u64]) {
    let errors: Vec<f32> = std::env::var("MDLOD_RENDER_ERRORS")
        .unwrap_or_else(|_| "1,2,4,8,16".into())
        .split(',')
        .filter_map(|s| s.trim().parse().ok())
        .collect();
    let (Some(&small), Some(&large)) = (sizes.first(), sizes.last()) else {
        return;
    };
    let files = [small, large].map(|n| MdlodFile::open(dataset(n)).unwrap());
    let opts = |error_px: f32| RenderOptions {
        width: W,
        height: H,
        view: ViewSpec::Orbit {
            azimuth_deg: 30.0,
            elevation_deg: 25.0,
            zoom: 1.0,
            projection: Projection::Perspective,
        },
        spp: 1,
        error_px,
        budget: u64::MAX,
        ..Default::default()
    };
    let mut rows = String::new();
    for &e in &errors {
        // (spheres, particles, GPU, traversal, cost) per size, medians of 5 after one
        // frame that warms the page cache and the renderer's buffers.
        let measure = |file: &MdlodFile| {
            render_image(renderer, file, &opts(e)).unwrap();
            let (mut gpu, mut trav, mut cost) = (vec![], vec![], vec![]);
            let mut last = None;
            for _ in 0..5 {
                let (_img, r) = render_image(renderer, file, &opts(e)).unwrap();
                let g = r.gpu_time.unwrap_or(r.total_time);
                gpu.push(g);
                trav.push(r.traversal_time);
                cost.push(g + r.traversal_time);
                last = Some(r);
            }
            let r = last.unwrap();
            (
                r.particles_drawn + r.nodes_drawn,
                r.particles_drawn,
                median(gpu),
                median(trav),
                median(cost),
            )
        };
        let [a, b] = [&files[0], &files[1]].map(measure);
        let row = format!(
            "| {e} | {} ({} particles) | {} ({} particles) | {:.1} / {:.1} | {:.1} / {:.1} | {:.1} / {:.1} | {:.2}× | **{:.2}×** |\n",
            a.0,
            a.1,
            b.0,
            b.1,
            ms(a.2),
            ms(b.2),
            ms(a.3),
            ms(b.3),
            ms(a.4),
            ms(b.4),
            b.2.as_secs_f64() / a.2.as_secs_f64(),
            b.4.as_secs_f64() / a.4.as_secs_f64(),
        );
        eprint!("{row}");
        rows.push_str(&row);
    }
    let (begin, end) = markers("-errors");
    let t = format!(
        "{begin} (generated by `MDLOD_RENDER_ONLY=errors cargo bench --bench render`; do not edit) -->\nAdapter: **{adapter}**. {small} against {large} crater particles, {W}×{H}, 1 sample per pixel, perspective view fitting the whole data set, occlusion culling, no budget; GPU time (timestamp queries) when the adapter has them, else wall time; medians of 5. Each pair of figures is {small} / {large}.\n\n| screen error px | spheres drawn, {small} | spheres drawn, {large} | GPU ms | traversal ms | frame cost ms (traversal + GPU) | GPU ratio | frame cost ratio (target ≤ 1.5×) |\n|---:|---:|---:|---:|---:|---:|---:|---:|\n{rows}{end}"
    );
    write_section(
        &begin,
        &end,
        &t,
        &format!("### Frame cost versus screen error on {adapter}"),
    );
}

/// Splat mode: frame time, splats drawn and the image's total flux against the
/// every-particle image, versus the screen error, in an orthographic view (where a
/// cluster's flux is exactly its particles'). Writes the `render-splat` section.
fn splat_table(renderer: &Renderer, adapter: &str, n: u64) {
    let file = MdlodFile::open(dataset(n)).unwrap();
    let mut rows = String::new();
    let mut reference = None;
    // The whole data set, orthographic, no budget.
    let splat_opts = |error_px: f32, mode: mdlod_render::RenderMode| RenderOptions {
        width: W,
        height: H,
        view: ViewSpec::Orbit {
            azimuth_deg: 30.0,
            elevation_deg: 25.0,
            zoom: 1.0,
            projection: Projection::Orthographic,
        },
        error_px,
        budget: u64::MAX,
        mode,
        ..Default::default()
    };
    for error_px in [0.0f32, 1.0, 4.0, 16.0, 64.0] {
        let opts = splat_opts(
            error_px,
            mdlod_render::RenderMode::Splat {
                by_attribute: false,
            },
        );
        let mut times = vec![];
        let mut last = None;
        for _ in 0..3 {
            let (_img, r) = render_image(renderer, &file, &opts).unwrap();
            times.push(r.gpu_time.unwrap_or(r.total_time));
            last = Some(r);
        }
        let r = last.unwrap();
        let flux = r.total_flux.unwrap();
        let reference = *reference.get_or_insert(flux);
        let row = format!(
            "| {error_px} | {} | {:.1} | {:.1} | {:.2e} |\n",
            r.particles_drawn + r.nodes_drawn,
            ms(median(times)),
            ms(r.traversal_time),
            (flux - reference).abs() / reference
        );
        eprint!("{row}");
        rows.push_str(&row);
    }
    // Sorted over-blending: the hierarchy's cluster order against every point sorted.
    let mut sorted_rows = String::new();
    for error_px in [0.0f32, 1.0, 4.0, 16.0] {
        let mut exact = None;
        for order in [
            mdlod_render::DepthOrder::Points,
            mdlod_render::DepthOrder::Clusters,
        ] {
            let opts = splat_opts(
                error_px,
                mdlod_render::RenderMode::SplatOver {
                    opacity: 0.8,
                    order,
                },
            );
            let (camera, traversal, _) = mdlod_render::frame_setup(&file, &opts).unwrap();
            let draw = mdlod_render::traverse(&camera, &file, &traversal);
            let mut sort_times = vec![];
            let mut frame_times = vec![];
            let mut image = None;
            for _ in 0..3 {
                let t = std::time::Instant::now();
                let sorted =
                    mdlod_render::traversal::sort_back_to_front_by(&file, &draw, &camera, order);
                sort_times.push(t.elapsed());
                drop(sorted);
                let (img, r) = render_image(renderer, &file, &opts).unwrap();
                frame_times.push(r.total_time - r.traversal_time);
                image = Some(img);
            }
            let image = image.unwrap();
            let differ = match &exact {
                None => {
                    exact = Some(image);
                    "(reference)".to_string()
                }
                Some(e) => {
                    let e: &mdlod_render::RgbaImage = e;
                    let n = e
                        .data
                        .chunks_exact(4)
                        .zip(image.data.chunks_exact(4))
                        .filter(|(a, b)| (0..3).any(|k| a[k].abs_diff(b[k]) > 2))
                        .count();
                    format!("{:.2} %", 100.0 * n as f64 / f64::from(W * H))
                }
            };
            let row = format!(
                "| {error_px} | {} | {} | {:.0} | {:.0} | {differ} |\n",
                draw.points,
                order.name(),
                ms(median(sort_times)),
                ms(median(frame_times)),
            );
            eprint!("{row}");
            sorted_rows.push_str(&row);
        }
    }
    let (begin, end) = markers("-splat");
    let t = format!(
        "{begin} (generated by `MDLOD_RENDER_ONLY=splat cargo bench --bench render`; do not edit) -->\nAdapter: **{adapter}**. {n} crater particles, {W}×{H}, orthographic view of the whole data set, no budget; GPU time (timestamp queries) when the adapter has them, else wall time; medians of 3. Flux error: the image's total flux against the every-particle image's.\n\n| screen error px | splats | frame ms | traversal ms | flux error |\n|---:|---:|---:|---:|---:|\n{rows}\nSorted over-blending (`--mode splat-over`, opacity 0.8): the hierarchy's order (clusters bucket-sorted by centroid depth, each cluster's points sorted; `--sort clusters`) against every point sorted (`--sort points`). Sort: host time of the ordering alone; frame: wall time after traversal (sorting, packing one range per point, drawing, read-back); pixels differing by more than 2/255 from the exact order's image.\n\n| screen error px | points | order | sort ms | frame ms | pixels differing |\n|---:|---:|---|---:|---:|---:|\n{sorted_rows}{end}"
    );
    write_section(
        &begin,
        &end,
        &t,
        "## Splatting: frame time and flux versus level",
    );
}

/// The density volume and its iso-surface: frame time (wall, the host waits for the
/// active-ray count between stacks), points splatted and slice stacks run, versus the
/// particle count. Writes the `render-density` section.
fn density_table(renderer: &Renderer, adapter: &str, sizes: &[u64]) {
    use mdlod_render::density::DensitySettings;
    let repeats = env_list("MDLOD_RENDER_REPEATS", "3")[0].max(1);
    let (w, h) = (
        env_list("MDLOD_DENSITY_WIDTH", "640")[0] as u32,
        env_list("MDLOD_DENSITY_HEIGHT", "360")[0] as u32,
    );
    let mut rows = String::new();
    let map = Some(mdlod_render::ColourMap::Viridis);
    for &n in sizes {
        let plain = MdlodFile::open(dataset(n)).unwrap();
        let with_ke = MdlodFile::open(dataset_with_ke(n)).unwrap();
        for (name, iso, colour_map) in [
            ("density", None, None),
            ("density by c_ke", None, map),
            ("iso 0.3", Some(0.3), None),
            ("iso 0.3 by c_ke", Some(0.3), map),
        ] {
            let file = if colour_map.is_some() {
                &with_ke
            } else {
                &plain
            };
            let opts = RenderOptions {
                width: w,
                height: h,
                view: ViewSpec::Orbit {
                    azimuth_deg: 30.0,
                    elevation_deg: 25.0,
                    zoom: 1.0,
                    projection: Projection::Perspective,
                },
                error_px: 1.0,
                mode: mdlod_render::RenderMode::Density(DensitySettings {
                    iso,
                    colour_map,
                    ..Default::default()
                }),
                ..Default::default()
            };
            // A first frame (no stack hint), then the same view again: the frame-to-frame
            // case, which runs the stacks the first needed in one batch.
            let mut times = vec![];
            let mut next_times = vec![];
            let mut host = vec![];
            let mut last = None;
            for _ in 0..repeats {
                renderer.clear_density_hint();
                let (_img, first) = render_image(renderer, file, &opts).unwrap();
                let (_img, next) = render_image(renderer, file, &opts).unwrap();
                times.push(first.total_time - first.traversal_time);
                next_times.push(next.total_time - next.traversal_time);
                host.push(first.density_host_time.unwrap_or_default());
                last = Some((first, next));
            }
            let (r, next) = last.unwrap();
            let (run, all) = r.density_stacks.unwrap();
            let (next_run, _) = next.density_stacks.unwrap();
            let (frame, next_frame, host) = (median(times), median(next_times), median(host));
            let row = format!(
                "| {n} | {name} | {} | {run} of {all} | {:.0} | {:.0} | {:.0} | {:.1} | {next_run}, {} read-back(s) against {} | {:.0} |\n",
                r.particles_drawn + r.nodes_drawn,
                ms(frame),
                ms(host),
                ms(frame.saturating_sub(host)),
                ms(r.traversal_time),
                next.density_readbacks.unwrap_or(0),
                r.density_readbacks.unwrap_or(0),
                ms(next_frame),
            );
            eprint!("{row}");
            rows.push_str(&row);
        }
    }
    let (begin, end) = markers("-density");
    let t = format!(
        "{begin} (generated by `MDLOD_RENDER_ONLY=density cargo bench --bench render`; do not edit) -->\nAdapter: **{adapter}**. Crater, {w}×{h}, perspective view of the whole data set, screen error 1 px, 256 slices (8 per stack; 4 with the attribute's sums for a volume coloured by it; 2 with gradients for the iso-surface), kernel 2.5 radii; rows `by c_ke` colour by the crater's kinetic energy (viridis; the same dump converted with `--attribute c_ke`); wall time of the frame after traversal: host prep (decoding, depth-sorting, packing the points) and the volume passes, medians of {repeats}. A first frame reads the active-ray count back after every 8 stacks; the next frame of the same view runs the stacks the first needed in one batch with one read-back (frame-to-frame coherence).\n\n| particles | mode | points | stacks run | frame ms | of which host prep ms | of which GPU passes ms | traversal ms | next frame: stacks, read-backs | next frame ms |\n|---:|---|---:|---:|---:|---:|---:|---:|---|---:|\n{rows}{end}"
    );
    write_section(
        &begin,
        &end,
        &t,
        "## Density volume: frame time versus particle count",
    );
}

/// The viewer's frames, as its render thread draws them (`render_image`: traversal,
/// upload, drawing, read-back to the host) at 1280×720: the refined frame at 1 px, and
/// the preview frame while moving after the viewer's own adaptation of the screen error
/// to the 33 ms target has settled (12 frames). Writes the `<section>-viewer` section.
fn viewer_table(renderer: &Renderer, adapter: &str, sizes: &[u64]) {
    use mdlod_viewer::state::{adapt_preview_error, preview_divisor};
    let target_ms = 33.0;
    let mut rows = String::new();
    for &n in sizes {
        let file = MdlodFile::open(dataset(n)).unwrap();
        // As the viewer draws a preview at an error in the window's pixels: a coarse one
        // smaller, with the same cut.
        let opts = |error_px: f32| RenderOptions {
            width: W.div_ceil(preview_divisor(error_px)),
            height: H.div_ceil(preview_divisor(error_px)),
            view: ViewSpec::Orbit {
                azimuth_deg: 30.0,
                elevation_deg: 25.0,
                zoom: 1.0,
                projection: Projection::Perspective,
            },
            error_px: error_px / preview_divisor(error_px) as f32,
            ..Default::default()
        };
        let frame = |e: f32| {
            let t = Instant::now();
            let (_, r) = render_image(renderer, &file, &opts(e)).unwrap();
            (t.elapsed(), r)
        };
        let refined = median((0..3).map(|_| frame(1.0).0).collect());
        // A light dragged over the refined view: each frame draws the cut kept from the
        // frame before under the next light (`render_image_keeping`).
        let mut kept = mdlod_render::KeptCut::default();
        let relit = median(
            (0..4)
                .map(|k| {
                    let mut o = opts(1.0);
                    o.lighting.direction_view =
                        mdlod_render::glam::Vec3::new(-0.4 + 0.2 * k as f32, 0.45, 1.0).normalize();
                    let t = Instant::now();
                    mdlod_render::render_image_keeping(renderer, &file, &o, &mut kept).unwrap();
                    t.elapsed()
                })
                .skip(1)
                .collect(),
        );
        assert_eq!(kept.chosen(), 1);
        let mut e = 1.0f32;
        for _ in 0..12 {
            let (t, _) = frame(e);
            e = adapt_preview_error(e, ms(t) as f32, target_ms, 1.0, preview_divisor(e));
        }
        let runs: Vec<_> = (0..3).map(|_| frame(e)).collect();
        let preview = median(runs.iter().map(|r| r.0).collect());
        let r = &runs[0].1;
        let d = preview_divisor(e);
        let row = format!(
            "| {n} | {:.0} | {:.0} | {e:.1} | {}×{} | {:.0} | {} |\n",
            ms(refined),
            ms(relit),
            W.div_ceil(d),
            H.div_ceil(d),
            ms(preview),
            r.particles_drawn + r.nodes_drawn
        );
        eprint!("{row}");
        rows.push_str(&row);
    }
    let (begin, end) = markers("-viewer");
    let t = format!(
        "{begin} (generated by `MDLOD_RENDER_ONLY=viewer cargo bench --bench render`; do not edit) -->\nAdapter: **{adapter}**. Crater, {W}×{H}, perspective view of the whole data set, one sample per pixel, budget 4 M spheres; wall time of `render_image` as the viewer's render thread calls it (traversal, upload, drawing, read-back), medians of 3. Re-lit: the refined view under another light, its cut kept (a light dragged over a still view). Preview: the screen error (in the window's pixels) after 12 frames of the viewer's adaptation to a {target_ms} ms target, and the size it draws a preview at that error (smaller from 4 px on, stretched over the window).\n\n| particles | refined frame ms (1 px) | re-lit frame ms | preview error px | preview drawn at | preview frame ms | preview spheres |\n|---:|---:|---:|---:|---|---:|---:|\n{rows}{end}"
    );
    write_section(&begin, &end, &t, "## Viewer: frame times");
}

/// The cut S-NDF sampling draws (whole-pixel occlusion, as the sndf mode takes), at a
/// screen error of 1 px and at most `budget` points.
fn sndf_cut(
    file: &MdlodFile,
    camera: &mdlod_render::Camera,
    viewport: [u32; 2],
    budget: u64,
) -> mdlod_render::DrawList {
    mdlod_render::traverse(
        camera,
        file,
        &mdlod_render::TraversalSettings {
            viewport,
            error_px: 1.0,
            budget_points: budget,
            occlusion: mdlod_render::OcclusionMode::WholePixels,
            ..Default::default()
        },
    )
}

/// S-NDFs of wide perspective views against the ray caster: at 30°, 60° and 90° fields of
/// view, the crater seen closely enough that it fills the image, re-lit S-NDFs (16
/// iterations, 8×8 bins, shaded on the host) against 16-spp ray casting under the same
/// light: the mean level of the image's outer band (a sixth of each side) and of its
/// middle, and the mean absolute difference. Writes the `<section>-sndf-wide` section.
fn sndf_wide_table(renderer: &Renderer, adapter: &str, n: u64) {
    use mdlod_render::sndf::{ShadeLights, SndfSettings};
    let file = MdlodFile::open(dataset(n)).unwrap();
    let (w, h, k) = (320u32, 180u32, 16u32);
    let fitted = mdlod_render::camera_for(
        &file,
        &ViewSpec::Orbit {
            azimuth_deg: 30.0,
            elevation_deg: 60.0,
            zoom: 1.0,
            projection: Projection::Perspective,
        },
        w,
        h,
    )
    .unwrap();
    let lights = [
        ("headlight", mdlod_render::glam::Vec3::Z),
        (
            "upper left (default)",
            mdlod_render::Lighting::default().direction_view,
        ),
    ];
    let mut rows = String::new();
    for fov in [30f32, 60.0, 90.0] {
        let mut camera = fitted.clone();
        // As close as the fit at 30°, then 0.4 of that: the slab fills the image.
        camera.distance *= 15f32.to_radians().tan() / (fov / 2.0).to_radians().tan() * 0.4;
        camera.fov_y_deg = fov;
        // Fitted again: the clip planes follow the new distance.
        let camera = mdlod_render::camera_for(&file, &ViewSpec::Camera(camera), w, h).unwrap();
        let draw = sndf_cut(&file, &camera, [w, h], 4_000_000);
        let sndf = renderer
            .sample_sndf(
                &file,
                &camera,
                &draw,
                &SndfSettings {
                    width: w,
                    height: h,
                    iterations: k,
                    bins: 8,
                    binning: Default::default(),
                },
            )
            .unwrap();
        for (name, direction) in lights {
            let lighting = mdlod_render::Lighting {
                direction_view: direction,
                ..Default::default()
            };
            let background = [0.0; 3];
            let relit = sndf.shade_with(&ShadeLights::from(&lighting), background);
            let opts = RenderOptions {
                width: w,
                height: h,
                view: ViewSpec::Camera(camera.clone()),
                spp: k,
                lighting,
                background,
                ..Default::default()
            };
            let (reference, _) = render_image(renderer, &file, &opts).unwrap();
            let (levels, reference_levels) = (
                relit.band_and_middle_levels(6),
                reference.band_and_middle_levels(6),
            );
            let ratio = |k: usize| (levels[k] / reference_levels[k] - 1.0) * 100.0;
            let mad = relit
                .data
                .iter()
                .zip(&reference.data)
                .map(|(a, b)| f64::from(a.abs_diff(*b)))
                .sum::<f64>()
                / relit.data.len() as f64;
            rows += &format!(
                "| {fov:.0}° | {name} | {:.1} | {:+.1} % | {:+.1} % | {mad:.2} |\n",
                reference_levels[0],
                ratio(0),
                ratio(1)
            );
        }
    }
    let (begin, end) = markers("-sndf-wide");
    let table = format!(
        "{begin} (generated by `MDLOD_RENDER_ONLY=sndf-wide cargo bench --bench render`; do not edit) -->\nAdapter: **{adapter}**. {n} crater particles, {w}×{h}, perspective views filled by the slab; 8×8 projected-normal bins binned along each texel's ray, {k} iterations, re-lit on the host, against {k}-spp ray casting under the same light (Blinn-Phong, the default material).\n\n| field of view | light | ray-cast level of the outer band (of 255) | S-NDFs against it, outer band | middle | mean absolute difference (of 255) |\n|---|---|---:|---:|---:|---:|\n{rows}{end}"
    );
    write_section(&begin, &end, &table, "## S-NDFs: sampling and re-lighting");
}

/// S-NDFs (`MDLOD_SNDF_BINS` bins per axis, default 8; `MDLOD_SNDF_SIZE=W,H`, default
/// 1280,720): one sampling iteration against
/// one plain ray-casting sample, re-lighting
/// against re-sampling at 256 spp, and the S-NDF memory, at 1280×720 (halved until the
/// histograms fit one buffer of the adapter). Writes the `<section>-sndf` section.
fn sndf_table(renderer: &Renderer, adapter: &str, n: u64) {
    use mdlod_render::sndf::{ShadeLights, SndfSettings};
    let file = MdlodFile::open(dataset(n)).unwrap();
    let limits = renderer.ctx.device.limits();
    let max = limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size);
    let bins = env_list("MDLOD_SNDF_BINS", "8")[0] as u32;
    let size = env_list("MDLOD_SNDF_SIZE", "1280,720");
    let (mut w, mut h, k) = (size[0] as u32, size[1] as u32, 16u32);
    while mdlod_render::sndf::sndf_buffer_bytes(w, h, bins) > max {
        w /= 2;
        h /= 2;
    }
    let view = ViewSpec::Orbit {
        azimuth_deg: 30.0,
        elevation_deg: 25.0,
        zoom: 1.0,
        projection: Projection::Perspective,
    };
    let opts = |spp: u32| RenderOptions {
        width: w,
        height: h,
        view: view.clone(),
        spp,
        ..Default::default()
    };
    let time = |r: &mdlod_render::RenderReport| r.gpu_time.unwrap_or(r.total_time);
    // Plain ray casting, K jittered samples, and 256.
    let plain = median(
        (0..3)
            .map(|_| time(&render_image(renderer, &file, &opts(k)).unwrap().1))
            .collect(),
    );
    let resample = time(&render_image(renderer, &file, &opts(256)).unwrap().1);
    // S-NDF sampling with the same cut (whole-pixel occlusion, as the sndf mode uses).
    let camera = mdlod_render::camera_for(&file, &view, w, h).unwrap();
    let draw = sndf_cut(&file, &camera, [w, h], 4_000_000);
    let settings = SndfSettings {
        width: w,
        height: h,
        iterations: k,
        bins,
        binning: Default::default(),
    };
    let mut sample_times = vec![];
    let mut sndf = None;
    for _ in 0..3 {
        let t = Instant::now();
        let s = renderer
            .sample_sndf(&file, &camera, &draw, &settings)
            .unwrap();
        sample_times.push(s.gpu_time.unwrap_or(t.elapsed()));
        sndf = Some(s);
    }
    let sndf = sndf.unwrap();
    let sampling = median(sample_times);
    // The marginal cost of an iteration: 3K iterations against K, for both (what
    // progressive refinement pays once buffers exist; the fixed costs cancel).
    let plain3 = median(
        (0..3)
            .map(|_| time(&render_image(renderer, &file, &opts(3 * k)).unwrap().1))
            .collect(),
    );
    let sampling3 = median(
        (0..3)
            .map(|_| {
                let t = Instant::now();
                let s = renderer
                    .sample_sndf(
                        &file,
                        &camera,
                        &draw,
                        &SndfSettings {
                            iterations: 3 * k,
                            ..settings
                        },
                    )
                    .unwrap();
                s.gpu_time.unwrap_or(t.elapsed())
            })
            .collect(),
    );
    let marginal = |a: Duration, b: Duration| b.saturating_sub(a) / (2 * k);
    let (plain_m, sndf_m) = (marginal(plain, plain3), marginal(sampling, sampling3));
    let lights = ShadeLights::from(&mdlod_render::Lighting::default());
    let host_relight = median(
        (0..5)
            .map(|_| {
                let t = Instant::now();
                std::hint::black_box(sndf.shade_linear(&lights, [1.0; 3]));
                t.elapsed()
            })
            .collect(),
    );
    // On the GPU: the shading pass alone (the S-NDFs stay resident after sampling).
    let relight = median(
        (0..5)
            .map(|_| {
                let t = Instant::now();
                let (_img, gpu) = renderer.shade_sndf(&sndf, &lights, [1.0; 3]).unwrap();
                gpu.unwrap_or(t.elapsed())
            })
            .collect(),
    );
    let k3 = 3 * k;
    let per_plain = plain / k;
    let per_sndf = sampling / k;
    let mib = (sndf.hist.len() * 16) as f64 / f64::from(1u32 << 20);
    let (begin, end) = markers("-sndf");
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let t = format!(
        "{begin} (generated by `MDLOD_RENDER_ONLY=sndf cargo bench --bench render`; do not edit) -->\nAdapter: **{adapter}**. {n} crater particles, {w}×{h}, perspective view of the whole data set, screen error 1 px; {bins}×{bins} projected-normal bins, {k} iterations. GPU times from timestamp queries when the adapter has them; re-lighting on the host ({threads} threads); medians.\n\n| measure | value |\n|---|---:|\n| one plain ray-casting sample, ms | {:.2} |\n| one S-NDF iteration (G-buffer + accumulation), ms | {:.2} |\n| **S-NDF iteration / plain sample** (target ≤ 1.10) | **{:.2}** |\n| marginal plain sample ({k} to {k3} spp), ms | {:.2} |\n| marginal S-NDF iteration ({k} to {k3} iterations), ms | {:.2} |\n| **marginal S-NDF iteration / marginal plain sample** | **{:.2}** |\n| re-sampling at 256 spp, ms | {:.1} |\n| re-lighting the S-NDFs on the GPU (shading pass), ms | {:.2} |\n| re-lighting on the host, ms | {:.1} |\n| **re-sampling / re-lighting (GPU)** (target ≥ 200) | **{:.0}** |\n| S-NDF memory, MiB | {mib:.0} |\n{end}",
        ms(per_plain),
        ms(per_sndf),
        per_sndf.as_secs_f64() / per_plain.as_secs_f64(),
        ms(plain_m),
        ms(sndf_m),
        sndf_m.as_secs_f64() / plain_m.as_secs_f64().max(1e-9),
        ms(resample),
        ms(relight),
        ms(host_relight),
        resample.as_secs_f64() / relight.as_secs_f64(),
    );
    write_section(&begin, &end, &t, "## S-NDFs: sampling and re-lighting");
}

/// The virtual S-MIP's navigation (`MDLOD_SMIP_SIZE=W,H`, default 1280,720, halved until
/// the tiles of a view and of its zoom-out fit one buffer): an orthographic view sampled
/// into a fresh cache, against a pan by a quarter of the width (only the new tiles are
/// sampled), a zoom-out by one level (down-sampled from the cached tiles, the border
/// sampled) and a fresh cache of that zoomed-out view; refinement and re-lighting; the
/// pool's memory. Writes the `<section>-smip` section.
fn smip_table(renderer: &Renderer, adapter: &str, n: u64) {
    use mdlod_render::smip::{min_radius, Smip, SmipConfig, SmipFrame};
    use mdlod_render::sndf::{tile_bytes, ShadeLights, TILE};
    // `MDLOD_SMIP_FILE` names an existing file instead (a large out-of-core one).
    let path = std::env::var_os("MDLOD_SMIP_FILE").map_or_else(|| dataset(n), PathBuf::from);
    let file = MdlodFile::open(&path).unwrap();
    let n = file.particle_count();
    let limits = renderer.ctx.device.limits();
    let max = limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size);
    let bins = env_list("MDLOD_SNDF_BINS", "8")[0] as u32;
    let k = env_list("MDLOD_SMIP_ITERATIONS", "16")[0] as u32;
    let budget = env_list("MDLOD_RENDER_BUDGET", "4000000")[0];
    let size = env_list("MDLOD_SMIP_SIZE", "1280,720");
    let (mut w, mut h) = (size[0] as u32, size[1] as u32);
    // A view's tiles with their bilinear margin, and a third more: the zoomed-out
    // view's tiles and the children they are down-sampled from (older tiles are
    // evicted).
    let pool_for = |w: u32, h: u32| (w.div_ceil(TILE) + 2) * (h.div_ceil(TILE) + 2) * 4 / 3;
    while u64::from(pool_for(w, h)) * tile_bytes(bins) > max {
        w /= 2;
        h /= 2;
    }
    let pool_tiles = pool_for(w, h);
    let style = mdlod_render::PointStyle::default();
    let camera = mdlod_render::camera_for(
        &file,
        &ViewSpec::Orbit {
            azimuth_deg: 30.0,
            elevation_deg: 25.0,
            zoom: 3.0,
            projection: Projection::Orthographic,
        },
        w,
        h,
    )
    .unwrap();
    let frame = SmipFrame::new(
        &camera,
        w,
        h,
        min_radius(&file, &style),
        1.0,
        bins,
        Default::default(),
        "bench".into(),
    )
    .unwrap();
    let new_cache = || {
        Smip::new(
            renderer,
            bins,
            SmipConfig {
                pool_tiles,
                budget_points: budget,
                ..Default::default()
            },
        )
        .unwrap()
    };
    let wait = || renderer.ctx.wait_idle().unwrap();
    let p = camera.view_height_at_target() / h as f32;
    let mut panned = camera.clone();
    panned.pan(w as f32 / 4.0 * p, 0.0);
    let mut zoomed = camera.clone();
    zoomed.zoom(0.5);
    // (wall time, stats) of preparing `to` in a cache that holds `from`.
    let timed = |from: Option<&mdlod_render::Camera>, to: &mdlod_render::Camera| {
        let mut cache = new_cache();
        if let Some(from) = from {
            cache
                .prepare(renderer, &file, &frame, from, w, h, k, &style)
                .unwrap();
            wait();
        }
        let t = Instant::now();
        let stats = cache
            .prepare(renderer, &file, &frame, to, w, h, k, &style)
            .unwrap();
        wait();
        (t.elapsed(), stats, cache)
    };
    let runs = |from: Option<&mdlod_render::Camera>, to: &mdlod_render::Camera| {
        let all: Vec<_> = (0..3).map(|_| timed(from, to)).collect();
        let time = median(all.iter().map(|r| r.0).collect());
        let (_, stats, cache) = all.into_iter().next_back().unwrap();
        (time, stats, cache)
    };
    let (full, full_stats, mut cache) = runs(None, &camera);
    let (pan, pan_stats, _) = runs(Some(&camera), &panned);
    let (zoom, zoom_stats, _) = runs(Some(&camera), &zoomed);
    let (zoom_fresh, zoom_fresh_stats, _) = runs(None, &zoomed);
    let refines: Vec<_> = (0..3)
        .map(|_| {
            let t = Instant::now();
            let stats = cache
                .refine(renderer, &file, &camera, w, h, 4, u32::MAX, &style)
                .unwrap();
            wait();
            (t.elapsed(), stats.gpu_time.unwrap_or_default())
        })
        .collect();
    let refine = median(refines.iter().map(|r| r.0).collect());
    let refine_gpu = median(refines.iter().map(|r| r.1).collect());
    let lights = ShadeLights::from(&mdlod_render::Lighting::default());
    // A drag as the viewer draws it: 16 frames, each a pan by 8 pixels, new tiles sampled
    // with one iteration, then shaded and read back; at the view's level and one level
    // coarser (what slow drags fall back to). Median and slowest frame.
    let drag = |bias: u32| {
        let mut c = new_cache();
        c.prepare(renderer, &file, &frame, &camera, w, h, k, &style)
            .unwrap();
        wait();
        c.set_level_bias(bias);
        let mut v = camera.clone();
        let times: Vec<Duration> = (0..16)
            .map(|_| {
                v.pan(8.0 * p, 0.0);
                let t = Instant::now();
                c.prepare(renderer, &file, &frame, &v, w, h, 1, &style)
                    .unwrap();
                c.shade(renderer, &v, w, h, &lights, [1.0; 3]).unwrap();
                t.elapsed()
            })
            .collect();
        let slowest = *times.iter().max().unwrap();
        (median(times), slowest)
    };
    let (drag0, drag1) = (drag(0), drag(1));
    // Perspective views are refined whole: a batch of 4 iterations with the S-NDFs kept
    // on the GPU (shaded there, the image read back), against the same batch sampled
    // into fresh histograms, read back and shaded on the host.
    let (resident_batch, host_batch) = {
        use mdlod_render::sndf::SndfSettings;
        let persp = mdlod_render::camera_for(&file, &ViewSpec::default(), w, h).unwrap();
        let draw = sndf_cut(&file, &persp, [w, h], budget);
        let settings = SndfSettings {
            width: w,
            height: h,
            iterations: 4,
            bins,
            binning: Default::default(),
        };
        let mut r = renderer
            .resident_sndf(&file, &persp, &draw, &settings, &style)
            .unwrap();
        renderer.refine_resident(&mut r, 4).unwrap();
        let resident = median(
            (0..3)
                .map(|_| {
                    let t = Instant::now();
                    renderer.refine_resident(&mut r, 4).unwrap();
                    renderer.shade_resident(&r, &lights, [1.0; 3]).unwrap();
                    t.elapsed()
                })
                .collect(),
        );
        let host = median(
            (1..4)
                .map(|i| {
                    let t = Instant::now();
                    let s = renderer
                        .sample_sndf_from(&file, &persp, &draw, &settings, 4 * i)
                        .unwrap();
                    std::hint::black_box(s.shade_with(&lights, [1.0; 3]));
                    t.elapsed()
                })
                .collect(),
        );
        (resident, host)
    };
    let shade = median(
        (0..5)
            .map(|_| {
                let t = Instant::now();
                let (_img, gpu) = cache
                    .shade(renderer, &camera, w, h, &lights, [1.0; 3])
                    .unwrap();
                gpu.unwrap_or(t.elapsed())
            })
            .collect(),
    );
    let row = |name: &str, t: Duration, s: &mdlod_render::smip::SmipStats| {
        format!(
            "| {name} | {:.1} | {} | {} | {} | {} | {} | {:.1} |\n",
            ms(t),
            s.needed,
            s.reused,
            s.sampled,
            s.downsampled,
            s.rects,
            s.particle_samples as f64 / 1e6,
        )
    };
    let rows = [
        row("fresh cache, the view", full, &full_stats),
        row("pan by a quarter width", pan, &pan_stats),
        row("zoom out by one level", zoom, &zoom_stats),
        row(
            "fresh cache, the zoomed-out view",
            zoom_fresh,
            &zoom_fresh_stats,
        ),
    ]
    .concat();
    let (begin, end) = markers("-smip");
    let file_mib = std::fs::metadata(&path).map_or(0.0, |m| m.len() as f64 / 1048576.0);
    let t = format!(
        "{begin} (generated by `MDLOD_RENDER_ONLY=smip cargo bench --bench render`; do not edit) -->\nAdapter: **{adapter}**. {n} crater particles, {w}×{h}, orthographic view zoomed 3× into the data set, level 0 at the view's pixels ({:.4} world units per texel), screen error 1 texel, at most {budget} spheres per 4×4 tiles sampled; {bins}×{bins} bins, {k} iterations per new tile; wall time including the GPU's work (traversal of each sampled rectangle, upload, drawing, accumulation, down-sampling), medians of 3. Pool: {pool_tiles} tiles of 64×64 texels, {:.0} MiB (one buffer; the adapter's largest is {} MiB).\n\n| step | ms | tiles needed | reused | sampled | down-sampled | rectangles | particle samples, M |\n|---|---:|---:|---:|---:|---:|---:|---:|\n{rows}\n| measure | value |\n|---|---:|\n| **pan / fresh view** | **{:.2}** |\n| **zoom-out by one level / fresh zoomed-out view** | **{:.2}** |\n| refining the view by 4 iterations, ms | {:.1} |\n| of which GPU (drawing and accumulation), ms | {:.1} |\n| re-lighting the view (composite pass, GPU), ms | {:.2} |\n| drag frame at the view's level (pan 8 px, new tiles 1 iteration, shaded, read back), median / slowest ms | {:.1} / {:.1} |\n| drag frame one level coarser, median / slowest ms | {:.1} / {:.1} |\n| perspective view, a refinement batch of 4 iterations kept on the GPU (shaded there, image read back), ms | {:.1} |\n| the same batch into fresh histograms, read back and shaded on the host, ms | {:.1} |\n| resident host memory after all steps, MiB (file: {file_mib:.0} MiB) | {:.0} |\n| of which the process's own (anonymous) / pages of mapped files, MiB | {:.0} / {:.0} |\n{end}",
        frame.texel0,
        cache.pool_bytes() as f64 / f64::from(1u32 << 20),
        max >> 20,
        pan.as_secs_f64() / full.as_secs_f64(),
        zoom.as_secs_f64() / zoom_fresh.as_secs_f64(),
        ms(refine),
        ms(refine_gpu),
        ms(shade),
        ms(drag0.0),
        ms(drag0.1),
        ms(drag1.0),
        ms(drag1.1),
        ms(resident_batch),
        ms(host_batch),
        rss_mib(),
        status_mib("RssAnon:"),
        status_mib("RssFile:"),
    );
    write_section(&begin, &end, &t, "## S-MIP: panning and zooming");
}

/// The last frame of the real 10^6-atom LAMMPS dump (datasets/lammps/make-large.sh) drawn
/// at 1280×720 by `mdlod render` (the whole process: open, adapter, traversal, drawing,
/// PNG) and by OVITO's OpenGL renderer (`render_image` only, the frame already loaded),
/// on the same machine. None when the dump or OVITO is missing.
fn ovito_side_by_side() -> Option<String> {
    let dump = std::fs::read_dir("data")
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("cu_large_") && n.ends_with(".dump"))
        })?;
    let mdlod = PathBuf::from("data/bench/cu_large.mdlod");
    if !mdlod.exists() {
        convert_file(
            &dump,
            &mdlod,
            FrameSelect::Last,
            &ReadOptions::default(),
            &ConvertOptions::default(),
            &NoProgress,
        )
        .ok()?;
    }
    let out = std::process::Command::new("python3")
        .args(["benches/ovito_render.py", dump.to_str()?, "3"])
        .output()
        .ok()?;
    if !out.status.success() {
        return None;
    }
    let ovito: Vec<Duration> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| l.trim().parse::<f64>().ok().map(Duration::from_secs_f64))
        .collect();
    let ours: Vec<Duration> = (0..3)
        .filter_map(|_| {
            let t = Instant::now();
            let ok = std::process::Command::new(env!("CARGO_BIN_EXE_mdlod"))
                .args(["render", mdlod.to_str()?, "-o", "data/bench/cu_large.png"])
                .args(["--azimuth", "45", "--elevation", "25"])
                .output()
                .ok()?
                .status
                .success();
            ok.then(|| t.elapsed())
        })
        .collect();
    if ovito.is_empty() || ours.is_empty() {
        return None;
    }
    let (o, m) = (median(ovito), median(ours));
    Some(format!(
        "\nThe last frame of a real 10^6-atom LAMMPS dump at 1280×720, side by side with OVITO's OpenGL renderer on the same machine: `mdlod render` {:.2} s for the whole process (open, adapter, traversal, drawing, PNG), OVITO `render_image` {:.2} s (frame already loaded): **{:.1}× faster** (target ≥ 4×).\n",
        m.as_secs_f64(),
        o.as_secs_f64(),
        o.as_secs_f64() / m.as_secs_f64()
    ))
}
