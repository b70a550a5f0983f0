//! [`GpuContext`]: the adapter, device and queue the GPU path runs on, picked once per process (or adopted
//! from the app), and the only place that creates GPU resources, so that they can be counted.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use crate::error::{HoloError, Result};

use super::kernel::Kernel;
use super::shaders::Shader;

/// How [`GpuContext::new`] picks an adapter.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct GpuOptions {
    /// Accept a software adapter (wgpu's `DeviceType::Cpu`, e.g. Mesa's lavapipe). Off by default: a CPU
    /// emulating a GPU is slower than the CPU path; the tests turn it on.
    pub allow_software: bool,
    /// Only adapters whose name contains this text (case-insensitive), e.g. `"llvmpipe"` or `"Apple"`.
    pub name_contains: Option<String>,
}

/// What the GPU path runs on, for logs, reports and `GeneratorInfo`.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct GpuInfo {
    /// Adapter name, e.g. "Apple A15 GPU", "llvmpipe (LLVM 15.0.6, 256 bits)".
    pub name: String,
    /// Graphics API: "vulkan" or "metal".
    pub backend: String,
    /// "discrete", "integrated", "virtual", "cpu" (software emulation) or "other".
    pub device_type: String,
    /// Driver name and version as the adapter reports them.
    pub driver: String,
    /// Whether the device has `SHADER_F16` (f16 arithmetic and storage in WGSL).
    pub shader_f16: bool,
    /// Largest storage-buffer binding in bytes (wgpu's default is 128 MiB; we request the adapter's own).
    pub max_storage_binding_bytes: u64,
    /// Largest buffer in bytes.
    pub max_buffer_bytes: u64,
}

impl GpuInfo {
    /// Whether the adapter is a CPU emulating a GPU (lavapipe, SwiftShader, WARP): its timings are not GPU
    /// timings, and [`crate::pipeline::Backend::Auto`] never picks it.
    pub fn is_software(&self) -> bool {
        self.device_type == "cpu"
    }
}

/// How many GPU objects a context has created so far ([`GpuContext::resource_counts`]); a session creates
/// all of its own up front, so these stay constant from frame to frame (tested).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct ResourceCounts {
    /// Buffers (storage, uniform, staging).
    pub buffers: usize,
    /// Compute pipelines.
    pub pipelines: usize,
    /// Bind groups.
    pub bind_groups: usize,
}

#[derive(Debug, Default)]
struct Counters {
    buffers: AtomicUsize,
    pipelines: AtomicUsize,
    bind_groups: AtomicUsize,
}

/// The adapter, device and queue of the GPU path. Cheap to clone (wgpu's handles are reference counted);
/// `Send + Sync`.
///
/// wgpu reports validation errors to a callback and would panic by default: the context records them
/// instead, and the next submission returns the first as [`HoloError::Gpu`]. A lost device (driver reset,
/// app backgrounded on iOS) makes every later call fail with [`HoloError::Gpu`]; the pipeline then falls
/// back to the CPU (`Backend::Auto`).
#[derive(Clone)]
pub struct GpuContext {
    device: wgpu::Device,
    queue: wgpu::Queue,
    info: Arc<GpuInfo>,
    counters: Arc<Counters>,
    errors: Arc<Mutex<Vec<String>>>,
    lost: Arc<AtomicBool>,
    modules: Arc<Mutex<HashMap<&'static str, wgpu::ShaderModule>>>,
}

impl std::fmt::Debug for GpuContext {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuContext")
            .field("info", &self.info)
            .field("counts", &self.resource_counts())
            .field("lost", &self.is_lost())
            .finish()
    }
}

fn gpu_err(what: impl std::fmt::Display) -> HoloError {
    HoloError::Gpu(what.to_string())
}

fn describe(info: &wgpu::AdapterInfo, features: wgpu::Features, limits: &wgpu::Limits) -> GpuInfo {
    GpuInfo {
        name: info.name.clone(),
        backend: format!("{:?}", info.backend).to_lowercase(),
        device_type: match info.device_type {
            wgpu::DeviceType::DiscreteGpu => "discrete",
            wgpu::DeviceType::IntegratedGpu => "integrated",
            wgpu::DeviceType::VirtualGpu => "virtual",
            wgpu::DeviceType::Cpu => "cpu",
            wgpu::DeviceType::Other => "other",
        }
        .to_string(),
        driver: format!("{} {}", info.driver, info.driver_info)
            .trim()
            .to_string(),
        shader_f16: features.contains(wgpu::Features::SHADER_F16),
        max_storage_binding_bytes: limits.max_storage_buffer_binding_size,
        max_buffer_bytes: limits.max_buffer_size,
    }
}

/// Whether a hardware GPU can exist for the drivers to find, by the device nodes the OS shows: on desktop
/// Linux a Vulkan driver for real hardware opens a DRM render node (`/dev/dri/renderD*`), NVIDIA's
/// `/dev/nvidia0` or WSL's `/dev/dxg`; without any of them only a software adapter (Mesa's lavapipe) can
/// answer, which [`Backend::Auto`](crate::pipeline::Backend::Auto) would refuse after loading the Vulkan
/// loader and every driver (≈ 50 MiB that stays resident: Mesa's drivers are never unloaded). Elsewhere
/// (Android, Apple, Windows) the drivers are asked: `true`.
pub(crate) fn hardware_gpu_possible() -> bool {
    #[cfg(all(target_os = "linux", not(target_os = "android")))]
    {
        let dri: Vec<String> = std::fs::read_dir("/dev/dri")
            .map(|d| {
                d.filter_map(|e| e.ok())
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .collect()
            })
            .unwrap_or_default();
        let other = ["/dev/nvidia0", "/dev/dxg"]
            .into_iter()
            .filter(|p| std::path::Path::new(p).exists());
        any_gpu_node(&dri, other)
    }
    #[cfg(not(all(target_os = "linux", not(target_os = "android"))))]
    {
        true
    }
}

/// `dri`: the names in `/dev/dri`; `other`: the other GPU device nodes that exist. A render node
/// (`renderD<N>`) or any other node means a hardware GPU may be there.
#[cfg_attr(
    not(all(target_os = "linux", not(target_os = "android"))),
    allow(dead_code)
)]
fn any_gpu_node<'a>(dri: &[String], mut other: impl Iterator<Item = &'a str>) -> bool {
    dri.iter().any(|n| {
        n.strip_prefix("renderD")
            .is_some_and(|d| !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit()))
    }) || other.next().is_some()
}

impl GpuContext {
    /// Picks an adapter (Vulkan or Metal, high performance first) as `options` say and opens a device with
    /// the adapter's own limits (so 1080p activations fit in one binding where the adapter allows) and
    /// `SHADER_F16` where it has it.
    ///
    /// Errors: [`HoloError::Gpu`] if no adapter matches (the message lists the adapters seen) or the device
    /// cannot be opened.
    pub fn new(options: &GpuOptions) -> Result<Self> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
            backends: wgpu::Backends::VULKAN | wgpu::Backends::METAL,
            ..wgpu::InstanceDescriptor::new_without_display_handle()
        });
        let adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
        let mut seen = Vec::new();
        let mut best: Option<(u8, wgpu::Adapter)> = None;
        for adapter in adapters {
            let info = adapter.get_info();
            seen.push(format!(
                "{} ({:?}, {:?})",
                info.name, info.backend, info.device_type
            ));
            if !options.allow_software && info.device_type == wgpu::DeviceType::Cpu {
                continue;
            }
            if let Some(want) = &options.name_contains {
                if !info.name.to_lowercase().contains(&want.to_lowercase()) {
                    continue;
                }
            }
            let rank = match info.device_type {
                wgpu::DeviceType::DiscreteGpu => 0,
                wgpu::DeviceType::IntegratedGpu => 1,
                wgpu::DeviceType::VirtualGpu | wgpu::DeviceType::Other => 2,
                wgpu::DeviceType::Cpu => 3,
            };
            if best.as_ref().is_none_or(|(r, _)| rank < *r) {
                best = Some((rank, adapter));
            }
        }
        let Some((_, adapter)) = best else {
            return Err(gpu_err(if seen.is_empty() {
                "no GPU adapter (no Vulkan or Metal driver found)".to_string()
            } else {
                format!(
                    "no GPU adapter matches ({}); adapters seen: {}",
                    if options.allow_software {
                        "any type".to_string()
                    } else {
                        "software adapters excluded".to_string()
                    } + &options
                        .name_contains
                        .as_ref()
                        .map(|n| format!(", name containing {n:?}"))
                        .unwrap_or_default(),
                    seen.join("; ")
                )
            }));
        };
        let features = adapter.features() & wgpu::Features::SHADER_F16;
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("tensorholo"),
            required_features: features,
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| gpu_err(format!("cannot open the GPU device: {e}")))?;
        Ok(Self::adopt(device, queue, &adapter.get_info()))
    }

    /// The process-wide context of [`GpuContext::new`] for `options`, created on first use and shared by every
    /// session that does not bring its own; re-created if its device was lost.
    ///
    /// Errors: as [`GpuContext::new`] (not cached: a later call tries again).
    pub(crate) fn shared(options: &GpuOptions) -> Result<Self> {
        static SHARED: Mutex<Vec<(GpuOptions, GpuContext)>> = Mutex::new(Vec::new());
        let mut shared = SHARED
            .lock()
            .map_err(|_| gpu_err("shared context lock poisoned"))?;
        shared.retain(|(_, c)| !c.is_lost());
        if let Some((_, ctx)) = shared.iter().find(|(o, _)| o == options) {
            return Ok(ctx.clone());
        }
        let ctx = Self::new(options)?;
        shared.push((options.clone(), ctx.clone()));
        Ok(ctx)
    }

    /// Adopts a device and queue the app already renders with, so that the hologram shares them (and the
    /// output buffers can be drawn without a copy through the CPU). `adapter` describes where they came from
    /// (`wgpu::Adapter::get_info`). The device's features and limits are read from it: f16 kernels run only
    /// if it was opened with `SHADER_F16`, and frames larger than its storage-binding limit are refused at
    /// session creation.
    ///
    /// This installs an uncaptured-error handler and a device-lost callback on `device` (replacing the app's).
    pub fn from_device(
        device: wgpu::Device,
        queue: wgpu::Queue,
        adapter: &wgpu::AdapterInfo,
    ) -> Self {
        Self::adopt(device, queue, adapter)
    }

    fn adopt(device: wgpu::Device, queue: wgpu::Queue, adapter: &wgpu::AdapterInfo) -> Self {
        let info = describe(adapter, device.features(), &device.limits());
        let errors = Arc::new(Mutex::new(Vec::new()));
        let lost = Arc::new(AtomicBool::new(false));
        {
            let log = Arc::clone(&errors);
            device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
                if let Ok(mut v) = log.lock() {
                    if v.len() < 16 {
                        v.push(e.to_string());
                    }
                }
            }));
            let flag = Arc::clone(&lost);
            let log = Arc::clone(&errors);
            device.set_device_lost_callback(move |reason, message| {
                flag.store(true, Ordering::SeqCst);
                if let Ok(mut v) = log.lock() {
                    v.push(format!("GPU device lost ({reason:?}): {message}"));
                }
            });
        }
        log::info!(
            "GPU: {} ({}, {}, f16 {})",
            info.name,
            info.backend,
            info.device_type,
            if info.shader_f16 { "yes" } else { "no" }
        );
        Self {
            device,
            queue,
            info: Arc::new(info),
            counters: Arc::default(),
            errors,
            lost,
            modules: Arc::default(),
        }
    }

    /// The adapter and device this context runs on.
    pub fn info(&self) -> &GpuInfo {
        &self.info
    }

    /// The wgpu device (to share with the app's own rendering).
    pub fn device(&self) -> &wgpu::Device {
        &self.device
    }

    /// The wgpu queue.
    pub(crate) fn queue(&self) -> &wgpu::Queue {
        &self.queue
    }

    /// Buffers, pipelines and bind groups created through this context (and its clones) so far.
    pub fn resource_counts(&self) -> ResourceCounts {
        ResourceCounts {
            buffers: self.counters.buffers.load(Ordering::Relaxed),
            pipelines: self.counters.pipelines.load(Ordering::Relaxed),
            bind_groups: self.counters.bind_groups.load(Ordering::Relaxed),
        }
    }

    /// Whether the device has been lost (every later call fails; make a new context).
    pub(crate) fn is_lost(&self) -> bool {
        self.lost.load(Ordering::SeqCst)
    }

    /// Returns (and clears) the errors wgpu reported since the last check, as one [`HoloError::Gpu`].
    pub(crate) fn take_error(&self) -> Result<()> {
        let mut errors = self
            .errors
            .lock()
            .map_err(|_| gpu_err("error log poisoned"))?;
        if self.is_lost() || !errors.is_empty() {
            let msg = if errors.is_empty() {
                "GPU device lost".to_string()
            } else {
                errors.join("; ")
            };
            errors.clear();
            return Err(gpu_err(msg));
        }
        Ok(())
    }

    /// Checks that a binding of `bytes` fits the device's limits.
    ///
    /// Errors: [`HoloError::Gpu`] naming `what`, the size and the limit.
    pub(crate) fn check_binding(&self, what: &str, bytes: u64) -> Result<()> {
        let limit = self
            .info
            .max_storage_binding_bytes
            .min(self.info.max_buffer_bytes);
        if bytes > limit {
            return Err(gpu_err(format!(
                "{what} needs a {:.1} MiB buffer, above this GPU's {:.1} MiB storage-binding limit; use a \
                 smaller frame or the CPU backend",
                bytes as f64 / 1048576.0,
                limit as f64 / 1048576.0
            )));
        }
        Ok(())
    }

    /// A zero-initialised buffer of `bytes` bytes (rounded up to 4) with `usage`.
    ///
    /// Errors: [`HoloError::Gpu`] if it exceeds the device's limits.
    pub(crate) fn buffer(
        &self,
        label: &str,
        bytes: u64,
        usage: wgpu::BufferUsages,
    ) -> Result<wgpu::Buffer> {
        let size = bytes.max(4).div_ceil(4) * 4;
        if usage.contains(wgpu::BufferUsages::STORAGE) {
            self.check_binding(label, size)?;
        }
        self.counters.buffers.fetch_add(1, Ordering::Relaxed);
        Ok(self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage,
            mapped_at_creation: false,
        }))
    }

    /// A storage buffer (also a copy source and destination) of `bytes` bytes.
    ///
    /// Errors: as [`GpuContext::buffer`].
    pub(crate) fn storage(&self, label: &str, bytes: u64) -> Result<wgpu::Buffer> {
        self.buffer(
            label,
            bytes,
            wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
        )
    }

    /// A storage buffer holding `data`.
    ///
    /// Errors: as [`GpuContext::buffer`].
    pub(crate) fn storage_with<T: bytemuck::Pod>(
        &self,
        label: &str,
        data: &[T],
    ) -> Result<wgpu::Buffer> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        let buf = self.storage(label, bytes.len() as u64)?;
        self.write(&buf, 0, bytes);
        Ok(buf)
    }

    /// A uniform buffer holding `value` (a `#[repr(C)]` struct matching the shader's, 16-byte aligned
    /// fields as WGSL lays them out).
    ///
    /// Errors: as [`GpuContext::buffer`].
    pub(crate) fn uniform<T: bytemuck::Pod>(&self, label: &str, value: &T) -> Result<wgpu::Buffer> {
        let bytes: &[u8] = bytemuck::bytes_of(value);
        let buf = self.buffer(
            label,
            bytes.len().max(16) as u64,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        )?;
        self.write(&buf, 0, bytes);
        Ok(buf)
    }

    /// Queues a write of `bytes` (length a multiple of 4) into `buffer` at `offset`; it happens before the
    /// next submission.
    pub(crate) fn write(&self, buffer: &wgpu::Buffer, offset: u64, bytes: &[u8]) {
        if !bytes.is_empty() {
            self.queue.write_buffer(buffer, offset, bytes);
        }
    }

    /// The compute pipeline of entry point `entry` in `shader` (the shader module is compiled once per
    /// context and reused by all its entry points).
    ///
    /// Errors: [`HoloError::Gpu`] if the shader does not compile or needs f16 the device lacks.
    pub(crate) fn kernel(&self, shader: &Shader, entry: &'static str) -> Result<Kernel> {
        if shader.f16 && !self.info.shader_f16 {
            return Err(gpu_err(format!(
                "{} needs SHADER_F16, which {} lacks",
                shader.name, self.info.name
            )));
        }
        let module = {
            let mut modules = self
                .modules
                .lock()
                .map_err(|_| gpu_err("shader cache poisoned"))?;
            modules
                .entry(shader.name)
                .or_insert_with(|| {
                    self.device
                        .create_shader_module(wgpu::ShaderModuleDescriptor {
                            label: Some(shader.name),
                            source: wgpu::ShaderSource::Wgsl(shader.source.into()),
                        })
                })
                .clone()
        };
        self.counters.pipelines.fetch_add(1, Ordering::Relaxed);
        let pipeline = self
            .device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: None,
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            });
        self.take_error()
            .map_err(|e| gpu_err(format!("{}::{entry}: {e}", shader.name)))?;
        Ok(Kernel::new(entry, pipeline))
    }

    /// A bind group for `kernel` with `buffers[i]` at `@binding(i)` of group 0.
    pub(crate) fn bind(&self, kernel: &Kernel, buffers: &[&wgpu::Buffer]) -> wgpu::BindGroup {
        let numbered: Vec<(u32, &wgpu::Buffer)> = buffers
            .iter()
            .enumerate()
            .map(|(i, b)| (i as u32, *b))
            .collect();
        self.bind_at(kernel, &numbered)
    }

    /// A bind group for `kernel` with each `(binding, buffer)` at `@binding(binding)` of group 0: for entry
    /// points that use only some of their module's bindings (the layout wgpu derives has only those).
    pub(crate) fn bind_at(
        &self,
        kernel: &Kernel,
        buffers: &[(u32, &wgpu::Buffer)],
    ) -> wgpu::BindGroup {
        self.counters.bind_groups.fetch_add(1, Ordering::Relaxed);
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .map(|(i, b)| wgpu::BindGroupEntry {
                binding: *i,
                resource: b.as_entire_binding(),
            })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(kernel.entry()),
            layout: &kernel.pipeline().get_bind_group_layout(0),
            entries: &entries,
        })
    }

    /// A command encoder.
    pub(crate) fn encoder(&self, label: &str) -> wgpu::CommandEncoder {
        self.device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) })
    }

    /// Submits `encoder` without waiting for it (a later [`GpuContext::submit_and_wait`] or read-back waits
    /// for every submission before it).
    ///
    /// Errors: [`HoloError::Gpu`] for a validation error or a lost device found so far.
    pub(crate) fn submit(&self, encoder: wgpu::CommandEncoder) -> Result<()> {
        self.take_error()?;
        self.queue.submit(Some(encoder.finish()));
        Ok(())
    }

    /// Submits `encoder` and blocks until the GPU has finished it.
    ///
    /// Errors: [`HoloError::Gpu`] for a validation error, a lost device or a failed wait.
    pub(crate) fn submit_and_wait(&self, encoder: wgpu::CommandEncoder) -> Result<()> {
        self.take_error()?;
        let index = self.queue.submit(Some(encoder.finish()));
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: Some(index),
                timeout: None,
            })
            .map_err(|e| gpu_err(format!("waiting for the GPU: {e}")))?;
        self.take_error()
    }

    /// Copies `dst.len()` bytes of the MAP_READ `staging` buffer (from its start) into `dst`, after a
    /// [`GpuContext::submit_and_wait`] that filled it.
    ///
    /// Errors: [`HoloError::Gpu`] if mapping fails.
    pub(crate) fn read_staging(&self, staging: &wgpu::Buffer, dst: &mut [u8]) -> Result<()> {
        if dst.is_empty() {
            return Ok(());
        }
        let len = (dst.len() as u64).div_ceil(4) * 4;
        let mapped = Arc::new(Mutex::new(None));
        {
            let mapped = Arc::clone(&mapped);
            staging.map_async(wgpu::MapMode::Read, 0..len, move |r| {
                if let Ok(mut m) = mapped.lock() {
                    *m = Some(r);
                }
            });
        }
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: None,
                timeout: None,
            })
            .map_err(|e| gpu_err(format!("waiting for a GPU read-back: {e}")))?;
        let status = mapped
            .lock()
            .map_err(|_| gpu_err("read-back poisoned"))?
            .take();
        match status {
            Some(Ok(())) => {}
            Some(Err(e)) => return Err(gpu_err(format!("cannot read GPU memory: {e}"))),
            None => return Err(gpu_err("GPU read-back did not complete")),
        }
        {
            let view = staging
                .get_mapped_range(0..len)
                .map_err(|e| gpu_err(format!("cannot read GPU memory: {e}")))?;
            dst.copy_from_slice(&view[..dst.len()]);
        }
        staging.unmap();
        self.take_error()
    }

    /// Test and debug helper (allocates): the first `len` elements of `buffer` as `T`s, through a new staging
    /// buffer. Frames use preallocated staging buffers instead.
    ///
    /// Errors: [`HoloError::Gpu`] if the copy or the mapping fails.
    pub(crate) fn read_buffer<T: bytemuck::Pod + Default>(
        &self,
        buffer: &wgpu::Buffer,
        len: usize,
    ) -> Result<Vec<T>> {
        let bytes = (len * std::mem::size_of::<T>()) as u64;
        let staging = self.buffer(
            "read_buffer",
            bytes,
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        )?;
        let mut enc = self.encoder("read_buffer");
        enc.copy_buffer_to_buffer(buffer, 0, &staging, 0, bytes.div_ceil(4) * 4);
        self.submit_and_wait(enc)?;
        let mut out = vec![T::default(); len];
        self.read_staging(&staging, bytemuck::cast_slice_mut(&mut out))?;
        Ok(out)
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::gpu::kernel::grid_1d;
    use crate::gpu::shaders;
    use crate::gpu::test_support::context as test_context;

    #[test]
    fn gpu_device_nodes_decide_whether_to_ask_the_drivers() {
        let names = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let none = std::iter::empty::<&str>;
        assert!(super::any_gpu_node(
            &names(&["card0", "renderD128"]),
            none()
        ));
        assert!(!super::any_gpu_node(
            &names(&["card0", "by-path", "renderD"]),
            none()
        ));
        assert!(!super::any_gpu_node(&[], none()));
        assert!(super::any_gpu_node(&[], ["/dev/nvidia0"].into_iter()));
    }

    #[repr(C)]
    #[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
    struct UtilParams {
        n: u32,
        value: f32,
        _pad: [u32; 2],
    }

    /// `util.wgsl`'s uniform beside its WGSL twin (checked in `shader_tests`).
    pub(in crate::gpu) fn uniform_layouts() -> Vec<crate::gpu::shader_tests::UniformLayout> {
        use crate::gpu::shader_tests::uniform_layout;
        vec![uniform_layout!(
            &shaders::UTIL,
            "Params",
            UtilParams { n, value }
        )]
    }

    #[test]
    fn fill_then_scale_round_trips_and_counts_resources() {
        let Some(ctx) = test_context() else { return };
        let n = 1000;
        let data = ctx.storage_with("data", &vec![1.0f32; n + 24]).unwrap();
        let fill = ctx.kernel(&shaders::UTIL, "fill").unwrap();
        let scale = ctx.kernel(&shaders::UTIL, "scale").unwrap();
        let p_fill = ctx
            .uniform(
                "fill",
                &UtilParams {
                    n: n as u32,
                    value: 3.0,
                    _pad: [0; 2],
                },
            )
            .unwrap();
        let p_scale = ctx
            .uniform(
                "scale",
                &UtilParams {
                    n: n as u32,
                    value: -0.5,
                    _pad: [0; 2],
                },
            )
            .unwrap();
        let bg_fill = ctx.bind(&fill, &[&p_fill, &data]);
        let bg_scale = ctx.bind(&scale, &[&p_scale, &data]);
        let before = ctx.resource_counts();
        for _ in 0..2 {
            let mut enc = ctx.encoder("test");
            {
                let mut pass = enc.begin_compute_pass(&Default::default());
                fill.dispatch(&mut pass, &bg_fill, grid_1d(n));
                scale.dispatch(&mut pass, &bg_scale, grid_1d(n));
            }
            ctx.submit_and_wait(enc).unwrap();
        }
        assert_eq!(ctx.resource_counts(), before, "a frame created GPU objects");
        let out: Vec<f32> = ctx.read_buffer(&data, n + 24).unwrap();
        assert!(out[..n].iter().all(|&v| v == -1.5), "{:?}", &out[..4]);
        assert!(
            out[n..].iter().all(|&v| v == 1.0),
            "wrote past n: {:?}",
            &out[n..]
        );
    }

    #[test]
    fn a_validation_error_is_a_typed_error_not_a_panic() {
        let Some(ctx) = test_context() else { return };
        let fill = ctx.kernel(&shaders::UTIL, "fill").unwrap();
        let p = ctx
            .uniform(
                "fill",
                &UtilParams {
                    n: 4,
                    value: 1.0,
                    _pad: [0; 2],
                },
            )
            .unwrap();
        // A uniform buffer where the shader wants a storage buffer: wgpu reports a validation error.
        let bg = ctx.bind(&fill, &[&p, &p]);
        let mut enc = ctx.encoder("bad");
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            fill.dispatch(&mut pass, &bg, grid_1d(4));
        }
        let err = ctx.submit_and_wait(enc).unwrap_err();
        assert!(matches!(err, HoloError::Gpu(_)), "{err}");
        // The context stays usable for the next, valid, work.
        let data = ctx.storage("data", 16).unwrap();
        let bg = ctx.bind(&fill, &[&p, &data]);
        let mut enc = ctx.encoder("good");
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            fill.dispatch(&mut pass, &bg, grid_1d(4));
        }
        ctx.submit_and_wait(enc).unwrap();
        assert_eq!(ctx.read_buffer::<f32>(&data, 4).unwrap(), vec![1.0; 4]);
    }
}
