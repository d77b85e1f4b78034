//! The one place that decides which GPU adapter and backend the renderer uses.
//!
//! Headless use (tests, `replay --headless`, benches) goes through [`GpuContext::new_headless`]:
//! it builds the instance with `InstanceDescriptor::new_without_display_handle_from_env()`, so
//! `WGPU_BACKEND` (and the other `WGPU_*` instance variables) are honoured, keeps only adapters
//! whose name contains `WGPU_ADAPTER_NAME` when that is set, and it prefers a CPU adapter
//! (Mesa lavapipe) when [`AdapterPreference::PreferCpu`] is asked for, so images are the same on
//! every machine. The window path (eframe) creates its own device; the renderer only needs a
//! `wgpu::Device` and `wgpu::Queue` (see [`crate::render::Renderer::new`]).
//!
//! Without any usable driver the result is [`DeviceError::NoAdapter`]. Tests turn that into a loud
//! skip, unless the environment variable [`REQUIRE_GPU_ENV`] is `1` (CI sets it), in which case
//! they fail: see [`gpu_required_by_env`].

/// Environment variable: when `1`, a missing GPU/driver is a test failure instead of a skip.
pub const REQUIRE_GPU_ENV: &str = "LEMAN_REQUIRE_GPU";

/// Which kind of adapter to prefer when several are available.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AdapterPreference {
    /// A CPU (software) adapter first, e.g. lavapipe: deterministic images for tests.
    #[default]
    PreferCpu,
    /// A discrete, then integrated GPU first; a CPU adapter only as the last resort.
    PreferHardware,
}

/// Failure to get a GPU device.
#[derive(Debug, thiserror::Error)]
pub enum DeviceError {
    /// No adapter at all (no Vulkan/GL driver; on Linux install `mesa-vulkan-drivers libvulkan1`).
    #[error(
        "no GPU adapter found for backends {backends:?} (WGPU_BACKEND={env_backend:?}); \
         on Linux without a GPU install Mesa lavapipe: apt-get install mesa-vulkan-drivers libvulkan1"
    )]
    NoAdapter {
        /// The backends that were searched.
        backends: wgpu::Backends,
        /// The value of `WGPU_BACKEND`, if set.
        env_backend: Option<String>,
    },
    /// An adapter was found but refused to create a device.
    #[error("GPU adapter {adapter} refused to create a device: {source}")]
    RequestDevice {
        /// Name and backend of the adapter.
        adapter: String,
        /// The wgpu error.
        #[source]
        source: wgpu::RequestDeviceError,
    },
}

/// Description of the chosen adapter, for logs and reports.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AdapterSummary {
    /// Adapter name as the driver reports it (e.g. `llvmpipe (LLVM 19.1.7, 256 bits)`).
    pub name: String,
    /// Backend (Vulkan, GL, ...).
    pub backend: wgpu::Backend,
    /// CPU, integrated GPU, discrete GPU, ...
    pub device_type: wgpu::DeviceType,
    /// Driver name and version.
    pub driver: String,
}

impl std::fmt::Display for AdapterSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} ({:?}, {:?}, driver {})",
            self.name, self.backend, self.device_type, self.driver
        )
    }
}

impl AdapterSummary {
    fn of(adapter: &wgpu::Adapter) -> Self {
        let info = adapter.get_info();
        Self {
            name: info.name,
            backend: info.backend,
            device_type: info.device_type,
            driver: format!("{} {}", info.driver, info.driver_info)
                .trim()
                .to_owned(),
        }
    }
}

/// A wgpu instance, adapter, device and queue chosen by this module.
#[derive(Debug, Clone)]
pub struct GpuContext {
    /// The instance the adapter came from.
    pub instance: wgpu::Instance,
    /// The chosen adapter.
    pub adapter: wgpu::Adapter,
    /// The logical device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// What was chosen, for logs.
    pub summary: AdapterSummary,
}

impl GpuContext {
    /// A device without any window: the instance honours `WGPU_BACKEND`; a CPU adapter is
    /// preferred (lavapipe), so images are reproducible.
    pub fn new_headless() -> Result<Self, DeviceError> {
        Self::new_headless_with(AdapterPreference::PreferCpu)
    }

    /// A device without any window, with an explicit adapter preference.
    pub fn new_headless_with(preference: AdapterPreference) -> Result<Self, DeviceError> {
        pollster::block_on(Self::new_headless_async(preference, None))
    }

    /// A device without any window on one of `backends` only, whatever `WGPU_BACKEND` says
    /// (e.g. to test the GL path on a machine that also has Vulkan).
    pub fn new_headless_on(
        backends: wgpu::Backends,
        preference: AdapterPreference,
    ) -> Result<Self, DeviceError> {
        pollster::block_on(Self::new_headless_async(preference, Some(backends)))
    }

    async fn new_headless_async(
        preference: AdapterPreference,
        only: Option<wgpu::Backends>,
    ) -> Result<Self, DeviceError> {
        let mut descriptor = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        if let Some(only) = only {
            descriptor.backends = only;
        }
        let backends = descriptor.backends;
        let instance = wgpu::Instance::new(descriptor);
        let mut adapters = instance.enumerate_adapters(backends).await;
        // `WGPU_ADAPTER_NAME` (as in wgpu's own helpers): keep adapters whose name contains it.
        if let Ok(wanted) = std::env::var("WGPU_ADAPTER_NAME") {
            let wanted = wanted.to_lowercase();
            adapters.retain(|a| a.get_info().name.to_lowercase().contains(&wanted));
        }
        adapters.sort_by_key(|a| {
            let info = a.get_info();
            adapter_rank(info.device_type, info.backend, preference)
        });
        let adapter = adapters
            .into_iter()
            .next()
            .ok_or_else(|| DeviceError::NoAdapter {
                backends,
                env_backend: std::env::var("WGPU_BACKEND").ok(),
            })?;
        let summary = AdapterSummary::of(&adapter);
        let (device, queue) = adapter
            .request_device(&device_descriptor(&adapter))
            .await
            .map_err(|source| DeviceError::RequestDevice {
                adapter: summary.to_string(),
                source,
            })?;
        tracing::info!(adapter = %summary, "render device chosen");
        Ok(Self {
            instance,
            adapter,
            device,
            queue,
            summary,
        })
    }
}

/// Whether `device` can view a texture in another format of the same layout (an RGBA8 sRGB
/// texture as RGBA8 unorm): wgpu's downlevel flag `VIEW_FORMATS`, which Vulkan, Metal and DX12
/// have and the GL backend never has. A device does not report its downlevel flags, so this
/// goes by its backend.
pub fn reinterprets_texture_formats(device: &wgpu::Device) -> bool {
    device.adapter_info().backend != wgpu::Backend::Gl
}

/// The device descriptor the renderer needs: default limits (downlevel for GL), no extra features.
pub fn device_descriptor(adapter: &wgpu::Adapter) -> wgpu::DeviceDescriptor<'static> {
    let base = if adapter.get_info().backend == wgpu::Backend::Gl {
        wgpu::Limits::downlevel_webgl2_defaults()
    } else {
        wgpu::Limits::default()
    };
    wgpu::DeviceDescriptor {
        label: Some("leman render device"),
        required_limits: wgpu::Limits {
            max_texture_dimension_2d: adapter.limits().max_texture_dimension_2d.min(8192),
            ..base
        },
        ..Default::default()
    }
}

/// Sort key: lower is better. Backend order Vulkan, Metal, DX12, GL; then device type by preference.
fn adapter_rank(
    device_type: wgpu::DeviceType,
    backend: wgpu::Backend,
    preference: AdapterPreference,
) -> (u8, u8) {
    let type_rank = match (preference, device_type) {
        (AdapterPreference::PreferCpu, wgpu::DeviceType::Cpu) => 0,
        (AdapterPreference::PreferCpu, wgpu::DeviceType::DiscreteGpu) => 1,
        (AdapterPreference::PreferCpu, _) => 2,
        (AdapterPreference::PreferHardware, wgpu::DeviceType::DiscreteGpu) => 0,
        (AdapterPreference::PreferHardware, wgpu::DeviceType::IntegratedGpu) => 1,
        (AdapterPreference::PreferHardware, wgpu::DeviceType::Cpu) => 3,
        (AdapterPreference::PreferHardware, _) => 2,
    };
    let backend_rank = match backend {
        wgpu::Backend::Vulkan => 0,
        wgpu::Backend::Metal => 1,
        wgpu::Backend::Dx12 => 2,
        wgpu::Backend::Gl => 3,
        wgpu::Backend::BrowserWebGpu => 4,
        wgpu::Backend::Noop => 5,
    };
    (type_rank, backend_rank)
}

/// True when the environment variable [`REQUIRE_GPU_ENV`] is `1`: a missing GPU must fail tests.
pub fn gpu_required_by_env() -> bool {
    std::env::var(REQUIRE_GPU_ENV).is_ok_and(|v| v.trim() == "1")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpu_adapter_wins_when_preferred_and_loses_otherwise() {
        use wgpu::{Backend, DeviceType};
        let rank = adapter_rank;
        let cpu_first = AdapterPreference::PreferCpu;
        let hw_first = AdapterPreference::PreferHardware;
        assert!(
            rank(DeviceType::Cpu, Backend::Vulkan, cpu_first)
                < rank(DeviceType::DiscreteGpu, Backend::Vulkan, cpu_first)
        );
        assert!(
            rank(DeviceType::Cpu, Backend::Vulkan, cpu_first)
                < rank(DeviceType::Cpu, Backend::Gl, cpu_first)
        );
        assert!(
            rank(DeviceType::DiscreteGpu, Backend::Vulkan, hw_first)
                < rank(DeviceType::Cpu, Backend::Vulkan, hw_first)
        );
    }
}
