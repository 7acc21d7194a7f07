//! Host memory across many frames (its own test binary: the only test in its process, so
//! that its measure of the process's memory is its own).
mod common;

use common::*;
use mdlod_render::{render_image, BackendChoice, GpuContext, RenderMode, RenderOptions, Renderer};

/// The process's anonymous resident memory, KiB (Linux); `None` elsewhere.
fn anonymous_kib() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("RssAnon:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// Frame after frame of one view, in the sphere and splat modes, the process's memory
/// stays flat. With the frame's parameters in uniform buffers, Mesa's software Vulkan
/// driver (lavapipe 22.3) compiled shader code every frame and kept it, about a megabyte
/// a frame (a movie of 10^4 frames, or a viewer left running, ran out of memory); with
/// the same parameters in storage buffers it does not. The shaders read them from
/// storage buffers.
#[test]
fn many_frames_keep_the_memory_flat() {
    let Some(start) = anonymous_kib() else {
        return;
    };
    let backends = if std::env::var_os("WGPU_BACKEND").is_some() {
        BackendChoice::FromEnv
    } else {
        BackendChoice::Only(wgpu::Backends::VULKAN)
    };
    let renderer = Renderer::new(GpuContext::with_backends(backends).unwrap());
    let (_dir, _, file) = make_file(&cloud_frame(300, 3), small_build(), &[]);
    for mode in [
        RenderMode::Spheres,
        RenderMode::Splat {
            by_attribute: false,
        },
    ] {
        let opts = RenderOptions {
            width: 32,
            height: 24,
            mode,
            backends,
            ..Default::default()
        };
        // Warm up (pipelines, pools, the allocator's first arenas), then measure.
        for _ in 0..10 {
            render_image(&renderer, &file, &opts).unwrap();
        }
        let before = anonymous_kib().unwrap_or(start);
        let frames = 60;
        for _ in 0..frames {
            render_image(&renderer, &file, &opts).unwrap();
        }
        let grown = anonymous_kib().unwrap_or(before).saturating_sub(before);
        assert!(
            grown < 8 * 1024,
            "{mode:?}: {frames} frames grew the process by {grown} KiB"
        );
    }
}
