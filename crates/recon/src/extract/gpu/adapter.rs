//! Adapter and device: which adapter [`GpuMode`] takes, opening the device with the adapter's
//! own limits and features, and collecting the errors wgpu reports (error scopes around a
//! sub-block, uncaptured errors, a lost device).

use std::sync::{Arc, Mutex};

use super::{GpuMode, GpuResult};

/// The names of the adapters wgpu finds (Vulkan, Metal, DirectX 12, or the backends named by
/// `WGPU_BACKEND`), with their type, for diagnostics and tests.
pub fn adapter_names() -> Vec<String> {
    let instance = make_instance();
    pollster::block_on(instance.enumerate_adapters(backends()))
        .iter()
        .map(|a| describe(&a.get_info()))
        .collect()
}

fn backends() -> wgpu::Backends {
    wgpu::Backends::from_env().unwrap_or(wgpu::Backends::PRIMARY)
}

fn make_instance() -> wgpu::Instance {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
    desc.backends = backends();
    desc.flags = wgpu::InstanceFlags::empty().with_env();
    wgpu::Instance::new(desc)
}

/// An adapter's name, type, backend and driver, for logs and errors.
pub(crate) fn describe(info: &wgpu::AdapterInfo) -> String {
    format!(
        "{} ({:?}, {:?}, {} {})",
        info.name, info.device_type, info.backend, info.driver, info.driver_info
    )
}

/// Preference among adapters: lower is better; `None` when `mode` does not take it.
fn rank(mode: GpuMode, t: wgpu::DeviceType) -> Option<u8> {
    use wgpu::DeviceType as T;
    match (mode, t) {
        (_, T::DiscreteGpu) => Some(0),
        (_, T::IntegratedGpu) => Some(1),
        (GpuMode::On, T::VirtualGpu) => Some(2),
        (GpuMode::On, T::Other) => Some(3),
        (GpuMode::On, T::Cpu) => Some(4),
        _ => None,
    }
}

/// The best adapter with compute shaders that `mode` takes, if any, and the adapters found
/// ("none" when there is none), for messages.
pub(crate) fn select(mode: GpuMode) -> (Option<wgpu::Adapter>, String) {
    let instance = make_instance();
    let adapters = pollster::block_on(instance.enumerate_adapters(backends()));
    let found: Vec<String> = adapters.iter().map(|a| describe(&a.get_info())).collect();
    let best = adapters
        .into_iter()
        .filter(|a| {
            a.get_downlevel_capabilities()
                .flags
                .contains(wgpu::DownlevelFlags::COMPUTE_SHADERS)
        })
        .filter_map(|a| rank(mode, a.get_info().device_type).map(|r| (r, a)))
        .min_by_key(|(r, _)| *r)
        .map(|(_, a)| a);
    let found = if found.is_empty() {
        "none".to_string()
    } else {
        found.join("; ")
    };
    (best, found)
}

/// The error of `OPTION on` (`--gpu`, `--gpu-solve`) when wgpu finds no adapter it can use;
/// `found` lists the adapters it found ([`select`]).
pub(crate) fn none_found(option: crate::error::Setting, found: &str) -> crate::error::Error {
    crate::error::Error::Usage(format!(
        "{option} on: wgpu found no GPU adapter with compute shaders (adapters: {found}); \
         install a Vulkan driver (Mesa's lavapipe is in mesa-vulkan-drivers) or use \
         {option} auto or off"
    ))
}

/// Errors that wgpu reports outside an error scope, and the reason a device was lost.
#[derive(Default)]
pub(crate) struct Trouble {
    /// The first uncaptured error since it was last taken.
    pub(crate) uncaptured: Option<String>,
    /// Why the device was lost, once it was.
    pub(crate) lost: Option<String>,
}

/// An opened device.
pub(crate) struct Opened {
    pub(crate) device: wgpu::Device,
    pub(crate) queue: wgpu::Queue,
    /// The adapter's limits, which the device was opened with.
    pub(crate) limits: wgpu::Limits,
    /// Whether shaders have 64-bit integers (`wgpu::Features::SHADER_INT64`), which build
    /// blended fields on the device (`field.wgsl`).
    pub(crate) int64: bool,
    /// Filled by the device's callbacks.
    pub(crate) trouble: Arc<Mutex<Trouble>>,
}

/// Open `adapter` with its own limits (not wgpu's defaults) and 64-bit integers in shaders
/// where it has them, with callbacks filling a [`Trouble`].
pub(crate) fn open_device(adapter: &wgpu::Adapter, info: &wgpu::AdapterInfo) -> GpuResult<Opened> {
    let limits = adapter.limits();
    let int64 = adapter.features().contains(wgpu::Features::SHADER_INT64);
    let required_features = if int64 {
        wgpu::Features::SHADER_INT64
    } else {
        wgpu::Features::empty()
    };
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("scanflow marching cubes"),
        required_features,
        required_limits: limits.clone(),
        experimental_features: wgpu::ExperimentalFeatures::disabled(),
        memory_hints: wgpu::MemoryHints::Performance,
        trace: wgpu::Trace::Off,
    }))
    .map_err(|e| format!("could not open {}: {e}", describe(info)))?;
    let trouble = Arc::new(Mutex::new(Trouble::default()));
    let t = Arc::clone(&trouble);
    device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
        if let Ok(mut t) = t.lock() {
            t.uncaptured.get_or_insert_with(|| e.to_string());
        }
    }));
    let t = Arc::clone(&trouble);
    device.set_device_lost_callback(move |reason, msg| {
        if let Ok(mut t) = t.lock() {
            t.lost
                .get_or_insert_with(|| format!("device lost ({reason:?}): {msg}"));
        }
    });
    Ok(Opened {
        device,
        queue,
        limits,
        int64,
        trouble,
    })
}

/// Error scopes for out of memory, validation and internal errors, pushed in that order.
pub(crate) fn push_scopes(device: &wgpu::Device) -> [wgpu::ErrorScopeGuard; 3] {
    [
        device.push_error_scope(wgpu::ErrorFilter::OutOfMemory),
        device.push_error_scope(wgpu::ErrorFilter::Validation),
        device.push_error_scope(wgpu::ErrorFilter::Internal),
    ]
}

/// Pop `scopes` (innermost first) and take what `trouble` holds: the errors, in that order,
/// and the reason the device was lost, if it was (also the last error).
pub(crate) fn pop_scopes(
    scopes: [wgpu::ErrorScopeGuard; 3],
    trouble: &Mutex<Trouble>,
) -> (Vec<String>, Option<String>) {
    let mut errors = Vec::new();
    for s in scopes.into_iter().rev() {
        if let Some(e) = pollster::block_on(s.pop()) {
            errors.push(e.to_string());
        }
    }
    let mut lost = None;
    if let Ok(mut t) = trouble.lock() {
        errors.extend(t.uncaptured.take());
        if let Some(l) = &t.lost {
            lost = Some(l.clone());
            errors.push(l.clone());
        }
    }
    (errors, lost)
}
