//! The wgpu device, created headless (no window, no surface): instance →
//! adapter → device, with the adapter's own limits so that large volumes
//! fit where the hardware allows. Errors are a `thiserror` enum naming the
//! limit or the step at fault.
//!
//! Backend and adapter follow wgpu's environment variables
//! (`WGPU_BACKEND=vulkan|gl|…`, `WGPU_ADAPTER_NAME=substring`,
//! `WGPU_POWER_PREF`), so CI can pin Mesa's lavapipe.

use std::sync::{Arc, Mutex};

/// What can go wrong in the GPU backend.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// No adapter (GPU or software rasteriser) is available.
    #[error("no GPU adapter available ({0}); install a Vulkan driver (e.g. Mesa's lavapipe, package mesa-vulkan-drivers) or use the CPU backend")]
    NoAdapter(String),
    /// The adapter refused to create a device (the reason is in the
    /// message, not also the error's source, so a full chain says it once).
    #[error("cannot create a GPU device on {adapter}: {reason}")]
    Device {
        /// The adapter's name.
        adapter: String,
        /// wgpu's reason.
        reason: wgpu::RequestDeviceError,
    },
    /// A buffer is larger than a device limit allows.
    #[error("the {what} needs {bytes} bytes, more than this device's {limit} ({max} bytes); use a smaller volume or image, or the CPU backend")]
    TooLarge {
        /// Which data (e.g. "density grid").
        what: String,
        /// Its size in bytes.
        bytes: u64,
        /// The name of the wgpu limit.
        limit: &'static str,
        /// The limit's value on this device.
        max: u64,
    },
    /// A 3D texture is larger along an axis than the device allows.
    #[error("the {what} is {dims} voxels, more than this device's max_texture_dimension_3d ({max} per axis); resample the volume or use the CPU backend")]
    TooManyVoxels {
        /// Which data (e.g. "density grid").
        what: String,
        /// Its size, "nx × ny × nz".
        dims: String,
        /// The limit's value on this device.
        max: u32,
    },
    /// wgpu reported an error (a shader that does not compile, a bad
    /// binding, out of memory).
    #[error("GPU error in {context}: {message}")]
    Wgpu {
        /// What was being done.
        context: String,
        /// wgpu's message.
        message: String,
    },
    /// A parameter beyond what the GPU backend supports.
    #[error("{what} = {value} exceeds the GPU backend's {max}; use the CPU backend")]
    Unsupported {
        /// The parameter (e.g. "N (series truncation)").
        what: &'static str,
        /// Its value.
        value: u64,
        /// The largest supported value.
        max: u64,
    },
    /// Reading results back from the GPU failed.
    #[error("reading back {what} failed: {message}")]
    Readback {
        /// Which buffer.
        what: &'static str,
        /// Why.
        message: String,
    },
}

/// A headless wgpu device and queue, with the adapter's description.
#[derive(Clone, Debug)]
pub struct GpuContext {
    /// The logical device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// The adapter it runs on (name, backend, device type).
    pub adapter_info: wgpu::AdapterInfo,
    /// The limits the device was created with (the adapter's).
    pub limits: wgpu::Limits,
    /// Errors wgpu reported outside an error scope, oldest first; checked
    /// by [`GpuContext::take_error`] instead of wgpu's default panic.
    uncaptured: Arc<Mutex<Vec<String>>>,
    /// Compute pipelines already built on this device, by module name and
    /// entry point (the previewer builds renderers on every edit; building
    /// a pipeline is far slower than a pass on a software rasteriser).
    pipelines: Arc<Mutex<Vec<PipelineEntry>>>,
}

/// One cached pipeline: (module name, entry point) and the pipeline.
type PipelineEntry = ((&'static str, &'static str), wgpu::ComputePipeline);

impl GpuContext {
    /// Creates a device on the first suitable adapter, without a window.
    pub fn new_headless() -> Result<Self, GpuError> {
        pollster::block_on(Self::new_headless_async())
    }

    async fn new_headless_async() -> Result<Self, GpuError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = instance
            .request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::from_env()
                    .unwrap_or(wgpu::PowerPreference::HighPerformance),
                ..Default::default()
            })
            .await
            .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let adapter = match std::env::var("WGPU_ADAPTER_NAME") {
            Ok(name) => pick_named(&instance, &name).await.unwrap_or(adapter),
            Err(_) => adapter,
        };
        let adapter_info = adapter.get_info();
        let limits = adapter.limits();
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("lantern device"),
                required_features: wgpu::Features::empty(),
                required_limits: limits.clone(),
                ..Default::default()
            })
            .await
            .map_err(|reason| GpuError::Device {
                adapter: adapter_info.name.clone(),
                reason,
            })?;
        Ok(Self::wrap(device, queue, adapter_info, limits))
    }

    /// A context on a device that someone else created, e.g. eframe's (so
    /// that renders and the window share one device and images need no
    /// copy). Fails with [`GpuError::NoAdapter`] where the adapter cannot
    /// run compute shaders (a GL ES fallback, say). From then on wgpu's
    /// errors outside an error scope on this device are collected for
    /// [`GpuContext::take_error`] instead of panicking, for every user of
    /// the device.
    pub fn from_device(
        adapter: &wgpu::Adapter,
        device: wgpu::Device,
        queue: wgpu::Queue,
    ) -> Result<Self, GpuError> {
        let adapter_info = adapter.get_info();
        let downlevel = adapter.get_downlevel_capabilities();
        if !downlevel
            .flags
            .contains(wgpu::DownlevelFlags::COMPUTE_SHADERS)
        {
            return Err(GpuError::NoAdapter(format!(
                "{} ({:?}) cannot run compute shaders",
                adapter_info.name, adapter_info.backend
            )));
        }
        let limits = device.limits();
        Ok(Self::wrap(device, queue, adapter_info, limits))
    }

    fn wrap(
        device: wgpu::Device,
        queue: wgpu::Queue,
        adapter_info: wgpu::AdapterInfo,
        limits: wgpu::Limits,
    ) -> Self {
        let uncaptured = Arc::new(Mutex::new(Vec::new()));
        let sink = uncaptured.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            if let Ok(mut v) = sink.lock() {
                v.push(e.to_string());
            }
        }));
        Self {
            device,
            queue,
            adapter_info,
            limits,
            uncaptured,
            pipelines: Arc::new(Mutex::new(Vec::new())),
        }
    }

    /// The pipeline built earlier for (`module`, `entry_point`), if any.
    pub fn cached_pipeline(
        &self,
        module: &'static str,
        entry_point: &'static str,
    ) -> Option<wgpu::ComputePipeline> {
        let cache = self.pipelines.lock().ok()?;
        cache
            .iter()
            .find(|(key, _)| *key == (module, entry_point))
            .map(|(_, p)| p.clone())
    }

    /// Keeps `pipeline` for later [`GpuContext::cached_pipeline`] calls.
    pub fn cache_pipeline(
        &self,
        module: &'static str,
        entry_point: &'static str,
        pipeline: &wgpu::ComputePipeline,
    ) {
        if let Ok(mut cache) = self.pipelines.lock() {
            cache.push(((module, entry_point), pipeline.clone()));
        }
    }

    /// One line describing the adapter, e.g. "llvmpipe (LLVM 15.0.6, 256
    /// bits) (Vulkan, Cpu)".
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {:?})",
            self.adapter_info.name, self.adapter_info.backend, self.adapter_info.device_type
        )
    }

    /// Whether the adapter is a software rasteriser (lavapipe, llvmpipe,
    /// WARP): timings then measure the CPU, not a GPU.
    pub fn is_software(&self) -> bool {
        self.adapter_info.device_type == wgpu::DeviceType::Cpu
    }

    /// Fails with [`GpuError::TooLarge`] if a storage buffer of `bytes`
    /// cannot be bound on this device.
    pub fn check_storage_size(&self, what: &str, bytes: u64) -> Result<(), GpuError> {
        let checks = [
            (
                "max_storage_buffer_binding_size",
                self.limits.max_storage_buffer_binding_size,
            ),
            ("max_buffer_size", self.limits.max_buffer_size),
        ];
        for (limit, max) in checks {
            if bytes > max {
                return Err(GpuError::TooLarge {
                    what: what.to_owned(),
                    bytes,
                    limit,
                    max,
                });
            }
        }
        Ok(())
    }

    /// The oldest error wgpu reported outside an error scope since the last
    /// call, as a [`GpuError`] about `context`.
    pub fn take_error(&self, context: &str) -> Result<(), GpuError> {
        let first = match self.uncaptured.lock() {
            Ok(mut v) => {
                let first = v.first().cloned();
                v.clear();
                first
            }
            Err(_) => None,
        };
        match first {
            Some(message) => Err(GpuError::Wgpu {
                context: context.to_owned(),
                message,
            }),
            None => Ok(()),
        }
    }

    /// Runs `f` inside a validation and out-of-memory error scope and
    /// returns its result, or the first error wgpu reported meanwhile.
    pub fn scoped<T>(&self, context: &str, f: impl FnOnce() -> T) -> Result<T, GpuError> {
        let oom = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let value = f();
        let errors = [
            pollster::block_on(validation.pop()),
            pollster::block_on(oom.pop()),
        ];
        match errors.into_iter().flatten().next() {
            Some(e) => Err(GpuError::Wgpu {
                context: context.to_owned(),
                message: e.to_string(),
            }),
            None => Ok(value),
        }
    }

    /// Blocks until the queue has finished all submitted work.
    pub fn wait_idle(&self) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Wgpu {
                context: "waiting for the GPU".to_owned(),
                message: e.to_string(),
            })?;
        self.take_error("GPU work")
    }
}

/// The first adapter whose name contains `name` (case-insensitive).
async fn pick_named(instance: &wgpu::Instance, name: &str) -> Option<wgpu::Adapter> {
    let name = name.to_lowercase();
    instance
        .enumerate_adapters(wgpu::Backends::all())
        .await
        .into_iter()
        .find(|a| a.get_info().name.to_lowercase().contains(&name))
}
