//! Choosing an adapter and opening a device for headless use. Embedding
//! apps skip this and hand their own device and queue to [`super::GpuSim`].
//! What blocks on the device (opening it, waiting, reading back) is native
//! only: a browser resolves a future only once its event loop runs, and
//! reads back through [`super::Readback`].

use crate::error::{Error, Result};

#[cfg(not(target_arch = "wasm32"))]
use bytemuck::Pod;
#[cfg(not(target_arch = "wasm32"))]
use std::sync::OnceLock;
use std::sync::{Arc, Mutex};

#[cfg(not(target_arch = "wasm32"))]
use crate::gpu::Kernels;
#[cfg(not(target_arch = "wasm32"))]
use crate::gpu::layout::VectorLayout;
#[cfg(not(target_arch = "wasm32"))]
use std::time::Duration;

/// A device and queue with what the simulator needs to know of them.
#[derive(Clone, Debug)]
pub struct GpuContext {
    /// The device the simulator runs on.
    pub device: wgpu::Device,
    /// The device's queue.
    pub queue: wgpu::Queue,
    /// The adapter the device was opened on, for logs and reports ([`describe`]).
    pub adapter: wgpu::AdapterInfo,
    /// The first validation error or device loss, recorded instead of
    /// panicking so a run can stop with one clear error.
    fault: Arc<Mutex<Option<String>>>,
    #[cfg(not(target_arch = "wasm32"))]
    kernels: KernelCache,
    /// The solver vectors' layout [`GpuContext::kernels`] compiles for;
    /// `None`: the adapter's ([`VectorLayout::for_adapter`]).
    #[cfg(not(target_arch = "wasm32"))]
    vectors: Option<VectorLayout>,
}

/// The kernels compiled for a context's device ([`GpuContext::kernels`]),
/// shared by its clones.
#[cfg(not(target_arch = "wasm32"))]
#[derive(Clone, Default)]
struct KernelCache(Arc<OnceLock<Arc<Kernels>>>);

#[cfg(not(target_arch = "wasm32"))]
impl std::fmt::Debug for KernelCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "KernelCache {{ compiled: {} }}", self.0.get().is_some())
    }
}

/// "name (backend, device type)" for logs and reports.
pub fn describe(info: &wgpu::AdapterInfo) -> String {
    format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type)
}

/// Whether the adapter does f32 arithmetic as the CPU twins do: a CPU
/// adapter (lavapipe) compiles WGSL with LLVM for this processor and
/// contracts no multiply-adds, so its stages agree with the CPU's to an ulp
/// or so and its solves take the CPU's iterations. A hardware GPU fuses
/// multiply-adds, and divides and takes square roots within the ulps WGSL
/// allows: on an NVIDIA H200 a spring's force differed by about an ulp of
/// its length, and its solves stopped an iteration earlier or later
/// ([`crate::sensitivity`]).
pub fn computes_as_the_cpu(info: &wgpu::AdapterInfo) -> bool {
    info.device_type == wgpu::DeviceType::Cpu
}

/// The features a headless device asks for where its adapter has them:
/// timestamp queries (the stages' timings) and subgroup operations (the
/// solver's workgroup sums, `wgsl/sums_subgroup.wgsl`).
pub const OPTIONAL_FEATURES: wgpu::Features = wgpu::Features::TIMESTAMP_QUERY
    .union(wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS)
    .union(wgpu::Features::SUBGROUP);

impl GpuContext {
    #[cfg(not(target_arch = "wasm32"))]
    /// A device on [`GpuContext::pick_adapter`]'s adapter, with what it has
    /// of [`OPTIONAL_FEATURES`].
    pub fn headless() -> Result<GpuContext> {
        Self::headless_with(OPTIONAL_FEATURES)
    }

    #[cfg(not(target_arch = "wasm32"))]
    /// [`GpuContext::headless`] asking for what the adapter has of `optional`
    /// (to compare a run without some of [`OPTIONAL_FEATURES`]).
    pub fn headless_with(optional: wgpu::Features) -> Result<GpuContext> {
        Self::from_adapter(&Self::pick_adapter()?, optional)
    }

    #[cfg(not(target_arch = "wasm32"))]
    /// Picks an adapter: `WGPU_BACKEND` limits the backends,
    /// `WGPU_ADAPTER_NAME` (a case-insensitive substring) picks by name,
    /// otherwise the high-performance default. Errors say which adapters
    /// exist when none fits.
    pub fn pick_adapter() -> Result<wgpu::Adapter> {
        // GL has no usable compute path here and its probing only adds
        // noise; WGPU_BACKEND can still ask for it.
        let backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::PRIMARY);
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
            backends,
            ..wgpu::InstanceDescriptor::new_without_display_handle_from_env()
        });
        let adapter = match std::env::var("WGPU_ADAPTER_NAME") {
            Ok(wanted) => {
                let adapters = pollster::block_on(instance.enumerate_adapters(backends));
                let names: Vec<String> = adapters.iter().map(|a| describe(&a.get_info())).collect();
                adapters
                    .into_iter()
                    .find(|a| a.get_info().name.to_lowercase().contains(&wanted.to_lowercase()))
                    .ok_or_else(|| {
                        Error::Gpu(format!(
                            "WGPU_ADAPTER_NAME={wanted:?} matches no adapter (found: {})",
                            if names.is_empty() { "none".into() } else { names.join("; ") }
                        ))
                    })?
            }
            Err(_) => pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                ..Default::default()
            }))
            .map_err(|e| {
                Error::Gpu(format!(
                    "no GPU adapter ({e}); on Debian `apt-get install mesa-vulkan-drivers` provides lavapipe"
                ))
            })?,
        };
        Ok(adapter)
    }

    #[cfg(not(target_arch = "wasm32"))]
    /// Opens a device on `adapter` with its full limits and what it has of
    /// the `optional` features (usually [`OPTIONAL_FEATURES`]).
    pub fn from_adapter(adapter: &wgpu::Adapter, optional: wgpu::Features) -> Result<GpuContext> {
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("wgcloth"),
            required_features: adapter.features() & optional,
            required_limits: adapter.limits(),
            ..Default::default()
        }))
        .map_err(|e| {
            Error::Gpu(format!(
                "cannot open a device on {}: {e}",
                describe(&adapter.get_info())
            ))
        })?;
        let fault: Arc<Mutex<Option<String>>> = Arc::default();
        let record = |fault: &Arc<Mutex<Option<String>>>, what: String| {
            let mut slot = fault.lock().unwrap_or_else(|e| e.into_inner());
            slot.get_or_insert(one_line(&what));
        };
        let f = fault.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| record(&f, e.to_string())));
        let f = fault.clone();
        device.set_device_lost_callback(move |reason, msg| {
            record(
                &f,
                format!("device lost ({reason:?}) {msg}")
                    .trim_end()
                    .to_string(),
            )
        });
        Ok(GpuContext {
            device,
            queue,
            adapter: adapter.get_info(),
            fault,
            kernels: KernelCache::default(),
            vectors: None,
        })
    }

    #[cfg(not(target_arch = "wasm32"))]
    /// This context with its kernels laying out the solver's vectors as
    /// `vectors`, not as suits the adapter (to compare the layouts).
    pub fn with_vectors(self, vectors: VectorLayout) -> GpuContext {
        GpuContext {
            kernels: KernelCache::default(),
            vectors: Some(vectors),
            ..self
        }
    }

    #[cfg(not(target_arch = "wasm32"))]
    /// The kernels for this device, compiled by the first call (about a
    /// second on lavapipe) and shared by every later one, and by the
    /// context's clones: each run of `wgcloth bench` on one device
    /// compiles nothing again.
    pub fn kernels(&self) -> Result<Arc<Kernels>> {
        if let Some(kernels) = self.kernels.0.get() {
            return Ok(kernels.clone());
        }
        let kernels = Arc::new(match self.vectors {
            Some(vectors) => Kernels::with_vectors(&self.device, vectors)?,
            None => Kernels::new(&self.device)?,
        });
        Ok(self.kernels.0.get_or_init(|| kernels).clone())
    }

    #[cfg(not(target_arch = "wasm32"))]
    /// Waits for submitted work and reports any fault the device recorded.
    pub fn finish(&self) -> Result<()> {
        wait(&self.device)?;
        self.fault()
    }

    /// Any fault the device has recorded so far (a lost device, an
    /// uncaptured error), without waiting.
    pub fn fault(&self) -> Result<()> {
        match self
            .fault
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .as_ref()
        {
            Some(what) => Err(Error::Gpu(what.clone())),
            None => Ok(()),
        }
    }
}

/// wgpu's multi-line error ("Validation Error", "Caused by:", the cause
/// indented) as one line: "Validation Error: cause: inner cause".
pub fn one_line(error: &str) -> String {
    error
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && *l != "Caused by:")
        .collect::<Vec<_>>()
        .join(": ")
}

#[cfg(not(target_arch = "wasm32"))]
/// The longest the host waits for submitted work: far beyond any step
/// (a 256² step takes about a second on lavapipe), so reaching it means a
/// hung or lost device, which then ends the run instead of hanging it.
pub const WATCHDOG: Duration = Duration::from_secs(120);

#[cfg(not(target_arch = "wasm32"))]
/// Waits for all submitted work, at most [`WATCHDOG`].
pub fn wait(device: &wgpu::Device) -> Result<()> {
    device
        .poll(wgpu::PollType::Wait {
            submission_index: None,
            timeout: Some(WATCHDOG),
        })
        .map(|_| ())
        .map_err(|e| match e {
            wgpu::PollError::Timeout => Error::Gpu(format!(
                "the device did not finish its work within {} s (hung or lost)",
                WATCHDOG.as_secs()
            )),
            e => Error::Gpu(format!("waiting for the device failed: {e}")),
        })
}

#[cfg(not(target_arch = "wasm32"))]
/// Copies `buffer` back to the host (blocks until the GPU is done), as
/// whole elements of `T` (small buffers are padded to 64 bytes).
pub fn read_buffer<T: Pod>(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    buffer: &wgpu::Buffer,
) -> Result<Vec<T>> {
    read_range(device, queue, buffer, 0..buffer.size())
}

#[cfg(not(target_arch = "wasm32"))]
/// [`read_buffer`] of the bytes `range` of `buffer` alone (its ends
/// multiples of 4: `wgpu::COPY_BUFFER_ALIGNMENT`).
pub fn read_range<T: Pod>(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    buffer: &wgpu::Buffer,
    range: std::ops::Range<u64>,
) -> Result<Vec<T>> {
    let size = range.end - range.start;
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    encoder.copy_buffer_to_buffer(buffer, range.start, &staging, 0, size);
    queue.submit([encoder.finish()]);
    let (tx, rx) = std::sync::mpsc::channel();
    staging.map_async(wgpu::MapMode::Read, .., move |r| {
        let _ = tx.send(r);
    });
    wait(device)?;
    rx.recv()
        .map_err(|_| Error::Gpu("readback never completed".into()))?
        .map_err(|e| Error::Gpu(format!("readback failed: {e}")))?;
    let view = staging
        .get_mapped_range(..)
        .map_err(|e| Error::Gpu(format!("readback failed: {e}")))?;
    let whole = view.len() / size_of::<T>() * size_of::<T>();
    Ok(bytemuck::pod_collect_to_vec(&view[..whole]))
}
