//! The GPU context: instance, adapter, device and queue.
//!
//! How it works: the backends come from `WGPU_BACKEND` when it is set (e.g. `vulkan`,
//! `gl`, `vulkan,gl`), otherwise all backends wgpu was built with. Every adapter of
//! those backends is listed and the best is taken: hardware before software
//! (discrete, integrated, virtual, then CPU), and among equals Vulkan before Metal and
//! DX12 before GL. `WGPU_ADAPTER_NAME` (a case-insensitive substring) narrows the list.
//! No adapter is [`RenderError::NoAdapter`], whose message says how to get one; it is
//! never a panic. The device is opened with the adapter's own limits (lavapipe's storage
//! buffer bindings are 128 MiB, the WebGPU defaults less) and with `TIMESTAMP_QUERY`
//! when the adapter has it, which [`GpuContext::timestamps`] reports.
//!
//! GPU errors are caught with error scopes around each piece of work (see
//! [`GpuContext::scoped`]); anything that still escapes is recorded instead of
//! panicking, and the next scoped call returns it as [`RenderError::Gpu`].

use std::sync::{Arc, Mutex};

use crate::error::RenderError;

/// Which backends to search.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BackendChoice {
    /// `WGPU_BACKEND` when set, else every backend.
    FromEnv,
    /// Exactly these backends (the environment is ignored); an empty mask finds nothing.
    Only(wgpu::Backends),
}

/// The backends of `mask` by the names `WGPU_BACKEND` takes (`vulkan, gl`), or `none`.
fn backend_names(mask: wgpu::Backends) -> String {
    let names: Vec<&str> = [
        (wgpu::Backends::VULKAN, "vulkan"),
        (wgpu::Backends::GL, "gl"),
        (wgpu::Backends::METAL, "metal"),
        (wgpu::Backends::DX12, "dx12"),
        (wgpu::Backends::BROWSER_WEBGPU, "webgpu"),
    ]
    .into_iter()
    .filter(|(b, _)| mask.contains(*b))
    .map(|(_, n)| n)
    .collect();
    if names.is_empty() {
        "none".to_string()
    } else {
        names.join(", ")
    }
}

/// An open device on the chosen adapter.
pub struct GpuContext {
    pub instance: wgpu::Instance,
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
    timestamps: bool,
    uncaptured: Arc<Mutex<Vec<String>>>,
}

impl std::fmt::Debug for GpuContext {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuContext")
            .field("adapter", &self.adapter_name())
            .finish_non_exhaustive()
    }
}

fn device_type_rank(t: wgpu::DeviceType) -> u8 {
    match t {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Cpu => 3,
        wgpu::DeviceType::Other => 4,
    }
}

fn backend_rank(b: wgpu::Backend) -> u8 {
    match b {
        wgpu::Backend::Vulkan => 0,
        wgpu::Backend::Metal | wgpu::Backend::Dx12 => 1,
        wgpu::Backend::Gl => 2,
        _ => 3,
    }
}

impl GpuContext {
    /// Opens the best adapter of the backends `WGPU_BACKEND` names (all when unset).
    pub fn new() -> Result<Self, RenderError> {
        Self::with_backends(BackendChoice::FromEnv)
    }

    /// Opens the best adapter among `choice`.
    pub fn with_backends(choice: BackendChoice) -> Result<Self, RenderError> {
        pollster::block_on(Self::open(choice))
    }

    async fn open(choice: BackendChoice) -> Result<Self, RenderError> {
        let env_value = std::env::var("WGPU_BACKEND").ok();
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        // Set but empty (`WGPU_BACKEND= mdlod ...`, a script's unset variable): as unset.
        let env_value = env_value.filter(|v| !v.trim().is_empty());
        if env_value.is_none() {
            desc.backends = wgpu::InstanceDescriptor::new_without_display_handle().backends;
        }
        let env_note = match choice {
            BackendChoice::FromEnv => match &env_value {
                Some(v) => format!(", WGPU_BACKEND={v}"),
                None => String::new(),
            },
            BackendChoice::Only(mask) => {
                desc.backends = mask;
                String::new()
            }
        };
        let backends = desc.backends;
        let no_adapter = || RenderError::NoAdapter {
            backends: backend_names(backends),
            env: env_note.clone(),
        };
        if backends.is_empty() {
            if let (BackendChoice::FromEnv, Some(v)) = (choice, &env_value) {
                return Err(RenderError::InvalidOptions(format!(
                    "WGPU_BACKEND={v} names no graphics backend: give vulkan, gl, metal or \
                     dx12 (several with commas), or leave it unset to try every one"
                )));
            }
            return Err(no_adapter());
        }
        let instance = wgpu::Instance::new(desc);
        let mut adapters = instance.enumerate_adapters(backends).await;
        if let Ok(name) = std::env::var("WGPU_ADAPTER_NAME") {
            let name = name.to_lowercase();
            adapters.retain(|a| a.get_info().name.to_lowercase().contains(&name));
        }
        adapters.sort_by_key(|a| {
            let info = a.get_info();
            (
                device_type_rank(info.device_type),
                backend_rank(info.backend),
            )
        });
        let Some(adapter) = adapters.into_iter().next() else {
            return Err(no_adapter());
        };
        let info = adapter.get_info();
        // Optional features, taken when the adapter has them: GPU timing, early depth
        // tests for the sphere pass's conservative depth, float blending for splats,
        // 64-bit atomics for the compute raster of small spheres.
        let required_features = adapter.features()
            & (wgpu::Features::TIMESTAMP_QUERY
                | wgpu::Features::SHADER_EARLY_DEPTH_TEST
                | wgpu::Features::FLOAT32_BLENDABLE
                | crate::passes::sphere_raycast::SMALL_SPHERES_FEATURES);
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("mdlod-render"),
                required_features,
                required_limits: adapter.limits(),
                ..Default::default()
            })
            .await
            .map_err(|e| RenderError::Device {
                adapter: info.name.clone(),
                message: e.to_string(),
            })?;
        let uncaptured = Arc::new(Mutex::new(Vec::new()));
        let sink = uncaptured.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            if let Ok(mut v) = sink.lock() {
                v.push(e.to_string());
            }
        }));
        Ok(GpuContext {
            instance,
            adapter,
            device,
            queue,
            info,
            timestamps: required_features.contains(wgpu::Features::TIMESTAMP_QUERY),
            uncaptured,
        })
    }

    /// Waits until the GPU has finished all submitted work (for wall-clock timings).
    pub fn wait_idle(&self) -> Result<(), RenderError> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| RenderError::Gpu(format!("waiting for the GPU: {e}")))
    }

    /// The adapter's name, e.g. `llvmpipe (LLVM 15.0.6, 256 bits)`.
    pub fn adapter_name(&self) -> &str {
        &self.info.name
    }

    /// The adapter's backend.
    pub fn backend(&self) -> wgpu::Backend {
        self.info.backend
    }

    /// The adapter's description as wgpu reports it.
    pub fn adapter_info(&self) -> &wgpu::AdapterInfo {
        &self.info
    }

    /// True when the device measures GPU time with timestamp queries.
    pub fn timestamps(&self) -> bool {
        self.timestamps
    }

    /// Runs `work` inside validation and out-of-memory error scopes and turns any GPU
    /// error it caused (or one recorded since the last call) into [`RenderError::Gpu`].
    pub fn scoped<T>(
        &self,
        work: impl FnOnce() -> Result<T, RenderError>,
    ) -> Result<T, RenderError> {
        let oom = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let result = work();
        let validation = pollster::block_on(validation.pop());
        let oom = pollster::block_on(oom.pop());
        if let Some(e) = validation.or(oom) {
            return Err(RenderError::Gpu(e.to_string()));
        }
        if let Ok(mut v) = self.uncaptured.lock() {
            if !v.is_empty() {
                let all = v.join("; ");
                v.clear();
                return Err(RenderError::Gpu(all));
            }
        }
        result
    }
}
