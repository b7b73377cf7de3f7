//! The GPU backend: one wgpu device per process, the WGSL kernels, and the host twins of their
//! job and prior structs.
//!
//! Kernels live in `shaders/`, one per file with entry point `main`; the shared code of
//! `shaders/shared/` is prepended to each (concatenation, never string replacement) by build.rs,
//! which validates every kernel with naga, so that one that does not compile fails the build. The
//! adapter follows `WGPU_BACKEND` (vulkan, metal, dx12; gl only where named) and
//! `WGPU_ADAPTER_NAME` (a case-insensitive substring of the adapter's name); its own limits are
//! requested. Pipelines are built once per context (`GpuContext::kernel`). The scoring kernels
//! come in two [`Shape`]s, chosen by measurement per adapter ([`tune`]) or by
//! `BITROCK_GPU_SHAPE`.

pub mod candidates;
pub mod coupled;
pub(crate) mod file_laws;
pub mod kernel_sums;
pub(crate) mod law_cases;
pub mod law_points;
pub mod records;
pub mod residual;
pub mod shape;
pub mod stability;
mod string_batch;
pub mod strings;
pub mod tune;
pub mod validator;

pub use shape::{SHAPE_VAR, Shape};

use crate::eval::Problem;
use crate::prior::Prior;
use bytemuck::{Pod, Zeroable};
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

/// A kernel's source as build.rs composed it (its shared files, then its own); naga validated
/// it at build time as [`built_in_kernel`] holds it.
macro_rules! kernel {
    ($name:literal) => {
        include_str!(concat!(env!("OUT_DIR"), "/shaders/", $name, ".wgsl"))
    };
}

/// A kernel's source without law files, as build.rs validated it.
#[cfg(test)]
macro_rules! built_in_kernel {
    ($name:literal) => {
        include_str!(concat!(env!("OUT_DIR"), "/shaders/", $name, ".built-in.wgsl"))
    };
}

/// The complete source of every kernel (shared files, then the kernel) and its entry points.
pub fn kernel_sources() -> Vec<(&'static str, String, &'static [&'static str])> {
    const SCORING: &[&str] = &[Shape::Blocked.entry_point(), Shape::Tiled.entry_point()];
    vec![
        ("residual", residual_source(), SCORING),
        ("candidates", candidates_source(), &["main"]),
        ("score_params", score_params_source(), SCORING),
        ("records", records_source(), SCORING),
        ("kernel_sums", kernel_sums_source(), &["main"]),
        ("slopes", slopes_source(), &["main"]),
        ("stability", stability_source(), &["main"]),
        ("strings", strings_source(), &["main", "on_clock"]),
        ("coupled", coupled_source(), &["main"]),
        (
            "coupled_without_subgroups",
            coupled_without_subgroups_source(),
            &["main"],
        ),
        ("test_uniform_between", test_uniform_between_source(), &["main"]),
    ]
}

/// The residual kernel with the law files' `laws` ([`file_laws::splice`]).
pub(crate) fn residual_source_for(laws: &[crate::Law]) -> String {
    file_laws::splice(kernel!("residual"), laws)
}

fn residual_source() -> String {
    residual_source_for(&[])
}

/// The score_params kernel with the law files' `laws` ([`file_laws::splice`]).
pub(crate) fn score_params_source_for(laws: &[crate::Law]) -> String {
    file_laws::splice(kernel!("score_params"), laws)
}

fn score_params_source() -> String {
    score_params_source_for(&[])
}

/// The records kernel with the law files' `laws` ([`file_laws::splice`]).
pub(crate) fn records_source_for(laws: &[crate::Law]) -> String {
    file_laws::splice(kernel!("records"), laws)
}

fn records_source() -> String {
    records_source_for(&[])
}

fn kernel_sums_source() -> String {
    kernel!("kernel_sums").to_string()
}

/// The slopes kernel with the law files' `laws` ([`file_laws::splice`]).
pub(crate) fn slopes_source_for(laws: &[crate::Law]) -> String {
    file_laws::splice(kernel!("slopes"), laws)
}

fn slopes_source() -> String {
    slopes_source_for(&[])
}

/// The strings kernel with the law files' `laws` ([`file_laws::splice`]).
/// The string kernel for `laws`, its state arrays as long as a chain of `nodes` (at most
/// [`crate::simulate::strings::MAX_NODES`]).
pub(crate) fn strings_source_for(laws: &[crate::Law], nodes: usize) -> String {
    const CHAIN_NODES: &str = "const CHAIN_NODES: u32 = 16u;";
    let source = file_laws::splice(kernel!("strings"), laws);
    debug_assert!(
        source.contains(CHAIN_NODES),
        "shaders/strings.wgsl declares CHAIN_NODES"
    );
    source.replace(CHAIN_NODES, &format!("const CHAIN_NODES: u32 = {nodes}u;"))
}

fn strings_source() -> String {
    strings_source_for(&[], crate::simulate::strings::MAX_NODES)
}

fn stability_source() -> String {
    kernel!("stability").to_string()
}

fn coupled_source() -> String {
    kernel!("coupled").to_string()
}

fn coupled_without_subgroups_source() -> String {
    kernel!("coupled_without_subgroups").to_string()
}

fn candidates_source() -> String {
    kernel!("candidates").to_string()
}

fn test_uniform_between_source() -> String {
    kernel!("test_uniform_between").to_string()
}

/// What can go wrong on the GPU, as text the user can act on.
#[derive(Clone, Debug, thiserror::Error)]
pub enum GpuError {
    #[error(
        "no GPU adapter: {0}. Install a Vulkan driver (for a software one: apt-get install mesa-vulkan-drivers libvulkan1), name OpenGL with WGPU_BACKEND=gl, or use `backend` cpu"
    )]
    NoAdapter(String),
    /// Adapters exist, but the environment names none of them for this process, or gives it
    /// none (`CUDA_VISIBLE_DEVICES` empty).
    #[error("no GPU for this process: {0}")]
    NotNamed(String),
    #[error("the GPU adapter refused a device: {0}")]
    RequestDevice(String),
    #[error("GPU validation error (a bug in bitrock; please report it): {0}")]
    Validation(String),
    #[error("the GPU ran out of memory: {0}; use fewer data points or `backend` cpu")]
    OutOfMemory(String),
    #[error("the GPU device was lost: {0}")]
    DeviceLost(String),
    #[error("the problem does not fit this GPU: {0}")]
    TooLarge(String),
    #[error("reading results back from the GPU failed: {0}")]
    Readback(String),
    /// A setting (environment variable) the user gave is refused: bad input.
    #[error("{name}: {message}")]
    Setting { name: &'static str, message: String },
}

impl From<GpuError> for crate::Error {
    /// A refused setting is the user's input (exit 2, naming the variable); the rest are
    /// failures of the GPU.
    fn from(e: GpuError) -> Self {
        match e {
            GpuError::Setting { name, message } => crate::Error::setting(name, message),
            e => crate::Error::Gpu(Box::new(e)),
        }
    }
}

/// The process's GPU: created once, shared by every evaluator.
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
    pub limits: wgpu::Limits,
    /// Set by the device-lost callback.
    lost: Arc<Mutex<Option<String>>>,
    /// Pipelines built so far, by label, entry point and override constants.
    kernels: Mutex<HashMap<String, Kernel>>,
}

/// A compute pipeline and the layout of its bind group 0.
#[derive(Clone, Debug)]
pub(crate) struct Kernel {
    pub pipeline: wgpu::ComputePipeline,
    pub layout: wgpu::BindGroupLayout,
}

static CONTEXT: OnceLock<Result<GpuContext, GpuError>> = OnceLock::new();

/// The process's GPU context, created on first use on the adapter the environment names
/// (see [`AdapterWish`]).
pub fn context() -> Result<&'static GpuContext, GpuError> {
    CONTEXT.get_or_init(create_context).as_ref().map_err(Clone::clone)
}

/// The environment variable that names the adapter: its index in [`adapters`]' list
/// (`bitrock devices` prints it) or its PCI bus id (`0000:3b:00.0`).
pub const ADAPTER_VAR: &str = "BITROCK_ADAPTER";

/// Which adapter the environment asks for, in this order: [`ADAPTER_VAR`];
/// `WGPU_ADAPTER_NAME` (a part of the adapter's name); `CUDA_VISIBLE_DEVICES` (what Slurm, Ray
/// and Dask give a GPU job: ordinal k is the k-th NVIDIA adapter in PCI bus order, CUDA's
/// order with `CUDA_DEVICE_ORDER=PCI_BUS_ID`; the first is a process's GPU; it says nothing
/// on a machine where wgpu sees no NVIDIA adapter); else wgpu's high-performance choice.
#[derive(Clone, Debug, PartialEq)]
pub enum AdapterWish {
    Any,
    Index(usize),
    BusId(String),
    Name(String),
    /// The ordinals `CUDA_VISIBLE_DEVICES` lists.
    CudaOrdinals(Vec<usize>),
    /// `CUDA_VISIBLE_DEVICES` hides every GPU (empty, or `-1`): the job was given none.
    NoneVisible,
}

impl AdapterWish {
    /// The wish of the environment `var` reads.
    pub fn from_env(var: impl Fn(&str) -> Option<String>) -> Result<Self, GpuError> {
        if let Some(value) = var(ADAPTER_VAR) {
            let value = value.trim().to_lowercase();
            return if let Ok(index) = value.parse() {
                Ok(AdapterWish::Index(index))
            } else if value.contains(':') {
                Ok(AdapterWish::BusId(value))
            } else {
                Err(GpuError::Setting {
                    name: ADAPTER_VAR,
                    message: format!(
                        "must be an adapter's index (`bitrock devices` lists them) or its PCI bus id such as 0000:3b:00.0, got `{value}`"
                    ),
                })
            };
        }
        if let Some(name) = var("WGPU_ADAPTER_NAME") {
            return Ok(AdapterWish::Name(name));
        }
        if let Some(visible) = var("CUDA_VISIBLE_DEVICES") {
            // CUDA stops at the first entry it cannot use; so does this.
            let mut ordinals = Vec::new();
            for entry in visible.split(',').map(str::trim) {
                match entry.parse::<i64>() {
                    Ok(k) if k >= 0 => ordinals.push(k as usize),
                    Ok(_) => break,
                    // A GPU or MIG UUID: not something wgpu reports; let wgpu choose.
                    Err(_) if !entry.is_empty() && ordinals.is_empty() => return Ok(AdapterWish::Any),
                    Err(_) => break,
                }
            }
            return Ok(if ordinals.is_empty() {
                AdapterWish::NoneVisible
            } else {
                AdapterWish::CudaOrdinals(ordinals)
            });
        }
        Ok(AdapterWish::Any)
    }

    /// The position in `adapters` of the adapter wished for; `None` when wgpu chooses.
    pub fn pick(&self, adapters: &[wgpu::AdapterInfo]) -> Result<Option<usize>, GpuError> {
        Ok(self.pick_all(adapters)?.and_then(|all| all.first().copied()))
    }

    /// The positions in `adapters` of every adapter wished for (`devices` all): the one
    /// named, every GPU `CUDA_VISIBLE_DEVICES` lists, or `None` when wgpu chooses.
    pub fn pick_all(&self, adapters: &[wgpu::AdapterInfo]) -> Result<Option<Vec<usize>>, GpuError> {
        let none = |why: String| Err(GpuError::NotNamed(why));
        let nvidia = nvidia_buses(adapters);
        match self {
            AdapterWish::Any => Ok(None),
            AdapterWish::NoneVisible | AdapterWish::CudaOrdinals(_) if nvidia.is_empty() => Ok(None),
            AdapterWish::NoneVisible => none("CUDA_VISIBLE_DEVICES gives this process no GPU".into()),
            AdapterWish::CudaOrdinals(ordinals) => ordinals
                .iter()
                .map(|&k| match nvidia.get(k) {
                    Some(bus) => Ok(primary_on_bus(adapters, bus)),
                    None => Err(GpuError::NotNamed(format!(
                        "CUDA_VISIBLE_DEVICES names NVIDIA GPU {k}, and wgpu sees {} NVIDIA adapters",
                        nvidia.len()
                    ))),
                })
                .collect::<Result<Vec<_>, _>>()
                .map(Some),
            one => one.pick_named(adapters).map(|i| Some(vec![i])),
        }
    }

    /// The position of the adapter an index, bus id or name picks.
    fn pick_named(&self, adapters: &[wgpu::AdapterInfo]) -> Result<usize, GpuError> {
        let none = |why: String| Err(GpuError::NotNamed(why));
        match self {
            AdapterWish::Index(i) if *i < adapters.len() => Ok(*i),
            AdapterWish::Index(i) => none(format!("{ADAPTER_VAR}={i}, but there are {} adapters", adapters.len())),
            AdapterWish::BusId(bus) => match adapters.iter().position(|a| same_bus(&a.device_pci_bus_id, bus)) {
                Some(i) => Ok(i),
                None => none(format!(
                    "{ADAPTER_VAR}={bus} matches no adapter's PCI bus id ({:?})",
                    adapters.iter().map(|a| &a.device_pci_bus_id).collect::<Vec<_>>()
                )),
            },
            AdapterWish::Name(wanted) => match adapters
                .iter()
                .position(|a| a.name.to_lowercase().contains(&wanted.to_lowercase()))
            {
                Some(i) => Ok(i),
                None => none(format!(
                    "WGPU_ADAPTER_NAME={wanted} matches none of {:?}",
                    adapters.iter().map(|a| &a.name).collect::<Vec<_>>()
                )),
            },
            _ => unreachable!("only a named adapter is picked by name"),
        }
    }
}

/// The PCI bus ids of the NVIDIA adapters, sorted: CUDA's ordinals under
/// `CUDA_DEVICE_ORDER=PCI_BUS_ID`.
fn nvidia_buses(adapters: &[wgpu::AdapterInfo]) -> Vec<&str> {
    let mut buses: Vec<&str> = adapters
        .iter()
        .filter(|a| a.vendor == NVIDIA && !a.device_pci_bus_id.is_empty())
        .map(|a| a.device_pci_bus_id.as_str())
        .collect();
    buses.sort_unstable();
    buses.dedup();
    buses
}

/// The adapter of the device on `bus` to compute with: its first one not through OpenGL
/// (wgpu lists a device once per backend).
fn primary_on_bus(adapters: &[wgpu::AdapterInfo], bus: &str) -> usize {
    let on_bus = || adapters.iter().enumerate().filter(|(_, a)| a.device_pci_bus_id == bus);
    on_bus()
        .find(|(_, a)| a.backend != wgpu::Backend::Gl)
        .or_else(|| on_bus().next())
        .map(|(i, _)| i)
        .expect("the bus came from the list")
}

/// Every GPU of the machine once (`devices` all when the environment names none): the
/// discrete and integrated adapters, one per device (by PCI bus id, else by name), through a
/// backend other than OpenGL where the device has one.
pub fn every_gpu(adapters: &[wgpu::AdapterInfo]) -> Vec<usize> {
    let gpu = |a: &wgpu::AdapterInfo| {
        matches!(
            a.device_type,
            wgpu::DeviceType::DiscreteGpu | wgpu::DeviceType::IntegratedGpu
        )
    };
    let id = |a: &wgpu::AdapterInfo| {
        if a.device_pci_bus_id.is_empty() {
            a.name.clone()
        } else {
            a.device_pci_bus_id.clone()
        }
    };
    let mut chosen: Vec<usize> = Vec::new();
    for (i, a) in adapters.iter().enumerate().filter(|(_, a)| gpu(a)) {
        match chosen.iter().position(|&c| id(&adapters[c]) == id(a)) {
            None => chosen.push(i),
            // The same device again: keep the one not through OpenGL.
            Some(k) if adapters[chosen[k]].backend == wgpu::Backend::Gl && a.backend != wgpu::Backend::Gl => {
                chosen[k] = i
            }
            Some(_) => {}
        }
    }
    chosen
}

/// PCI vendor id of NVIDIA.
const NVIDIA: u32 = 0x10de;

/// True when bus ids `a` and `b` name the same device (the domain `0000:` may be left out).
fn same_bus(a: &str, b: &str) -> bool {
    let strip = |s: &str| -> String {
        let s = s.trim().to_lowercase();
        if s.matches(':').count() == 2 {
            s
        } else {
            format!("0000:{s}")
        }
    };
    !a.is_empty() && strip(a) == strip(b)
}

/// The backends a device may come through: those `WGPU_BACKEND` names, else every one but
/// OpenGL. wgpu's OpenGL backend serialises a device's work behind one context lock and panics
/// where a thread waits on it for more than a second (seen with Mesa's llvmpipe when one
/// thread's dispatch ran long while another released a buffer): a process that scores from
/// several threads cannot rely on it, so it is used only where named.
fn backends() -> wgpu::Backends {
    backends_named(std::env::var("WGPU_BACKEND").ok().as_deref())
}

/// [`backends`] where `WGPU_BACKEND` is `named` (a comma-separated list, as wgpu reads it).
fn backends_named(named: Option<&str>) -> wgpu::Backends {
    named.map_or(
        wgpu::Backends::all().difference(wgpu::Backends::GL),
        wgpu::Backends::from_comma_list,
    )
}

/// A wgpu instance on [`backends`], its other options from the environment.
fn instance() -> wgpu::Instance {
    wgpu::Instance::new(wgpu::InstanceDescriptor {
        backends: backends(),
        ..wgpu::InstanceDescriptor::new_without_display_handle_from_env()
    })
}

/// The adapters wgpu sees (on the backends `WGPU_BACKEND` names, else every one but OpenGL),
/// in the order [`ADAPTER_VAR`] indexes.
pub fn adapters() -> Vec<wgpu::AdapterInfo> {
    pollster::block_on(instance().enumerate_adapters(backends()))
        .iter()
        .map(wgpu::Adapter::get_info)
        .collect()
}

fn create_context() -> Result<GpuContext, GpuError> {
    let instance = instance();
    let wish = AdapterWish::from_env(|name| std::env::var(name).ok())?;
    let named = match wish {
        AdapterWish::Any => None,
        wish => {
            let mut adapters = pollster::block_on(instance.enumerate_adapters(backends()));
            let infos: Vec<wgpu::AdapterInfo> = adapters.iter().map(wgpu::Adapter::get_info).collect();
            wish.pick(&infos)?.map(|at| adapters.swap_remove(at))
        }
    };
    let adapter = match named {
        Some(adapter) => adapter,
        None => pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::from_env().unwrap_or(wgpu::PowerPreference::HighPerformance),
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoAdapter(e.to_string()))?,
    };
    context_on(adapter)
}

/// The context of every GPU this process may use, each created once (`devices` all): those
/// the environment names ([`AdapterWish::pick_all`]), else every GPU of the machine
/// ([`every_gpu`]). A machine without a GPU adapter gives the one [`context`] picks (a CPU
/// driver such as lavapipe).
pub fn every_context() -> Result<Vec<&'static GpuContext>, GpuError> {
    static ALL: OnceLock<Result<Vec<&'static GpuContext>, GpuError>> = OnceLock::new();
    ALL.get_or_init(|| {
        let wish = AdapterWish::from_env(|name| std::env::var(name).ok())?;
        let mut adapters: Vec<Option<wgpu::Adapter>> = pollster::block_on(instance().enumerate_adapters(backends()))
            .into_iter()
            .map(Some)
            .collect();
        let infos: Vec<wgpu::AdapterInfo> = adapters.iter().flatten().map(wgpu::Adapter::get_info).collect();
        let chosen = wish.pick_all(&infos)?.unwrap_or_else(|| every_gpu(&infos));
        if chosen.is_empty() {
            return Ok(vec![context()?]);
        }
        chosen
            .into_iter()
            .map(|i| {
                let adapter = adapters[i].take().expect("each adapter is chosen once");
                Ok(&*Box::leak(Box::new(context_on(adapter)?)))
            })
            .collect()
    })
    .clone()
}

/// A context on `adapter`: its device and queue, with the adapter's own limits.
fn context_on(adapter: wgpu::Adapter) -> Result<GpuContext, GpuError> {
    let info = adapter.get_info();
    let limits = adapter.limits();
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("bitrock"),
        // Subgroup operations where the adapter has them (the coupled kernel's `any_lane`).
        required_features: adapter.features() & wgpu::Features::SUBGROUP,
        required_limits: limits.clone(),
        experimental_features: wgpu::ExperimentalFeatures::disabled(),
        memory_hints: wgpu::MemoryHints::Performance,
        trace: wgpu::Trace::Off,
    }))
    .map_err(|e| GpuError::RequestDevice(e.to_string()))?;
    let lost = Arc::new(Mutex::new(None));
    let field = lost.clone();
    device.set_device_lost_callback(move |reason, message| {
        *field.lock().expect("device-lost field") = Some(format!("{reason:?}: {message}"));
    });
    Ok(GpuContext {
        device,
        queue,
        info,
        limits,
        lost,
        kernels: Mutex::new(HashMap::new()),
    })
}

impl GpuContext {
    /// Whether the adapter is a software driver on the CPU (lavapipe, SwiftShader).
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    /// Whether the device was created with subgroup operations (the adapter has them).
    pub fn has_subgroups(&self) -> bool {
        self.device.features().contains(wgpu::Features::SUBGROUP)
    }

    /// One line naming the adapter, for logs and reports.
    pub fn describe(&self) -> String {
        let i = &self.info;
        format!(
            "{} ({:?}, {:?}, driver {} {})",
            i.name, i.backend, i.device_type, i.driver, i.driver_info
        )
    }

    /// Fails if the device was lost since the last check.
    fn check_lost(&self) -> Result<(), GpuError> {
        match self.lost.lock().expect("device-lost field").clone() {
            Some(message) => Err(GpuError::DeviceLost(message)),
            None => Ok(()),
        }
    }

    /// Runs `f` inside validation and out-of-memory error scopes, turning captured errors into
    /// typed ones.
    fn scoped<T>(&self, f: impl FnOnce() -> T) -> Result<T, GpuError> {
        let oom = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let value = f();
        if let Some(e) = pollster::block_on(validation.pop()) {
            return Err(GpuError::Validation(e.to_string()));
        }
        if let Some(e) = pollster::block_on(oom.pop()) {
            return Err(GpuError::OutOfMemory(e.to_string()));
        }
        self.check_lost()?;
        Ok(value)
    }

    /// A command encoder labelled `label`.
    fn encoder(&self, label: &str) -> wgpu::CommandEncoder {
        self.device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) })
    }

    /// Writes `job` into its uniform `job_buffer` and records a dispatch of `kernel` over `grid`
    /// into `encoder`. Where another dispatch follows (`more`), this one is submitted at once and
    /// `encoder` starts anew: a queued write lands before every command submitted after it, so
    /// the next job must not be written while this one waits unsubmitted.
    #[allow(clippy::too_many_arguments)]
    fn dispatch_job<J: bytemuck::Pod>(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        label: &str,
        kernel: &Kernel,
        group: &wgpu::BindGroup,
        (job_buffer, job): (&wgpu::Buffer, &J),
        grid: (u32, u32),
        more: bool,
    ) -> Result<(), GpuError> {
        self.queue.write_buffer(job_buffer, 0, bytemuck::bytes_of(job));
        encode_dispatch(encoder, label, &kernel.pipeline, group, grid);
        if more {
            let recorded = std::mem::replace(encoder, self.encoder(label));
            self.scoped(|| self.queue.submit([recorded.finish()]))?;
        }
        Ok(())
    }

    /// The compute pipeline of entry point `entry` of `source` (called only when the pipeline
    /// is not built yet: once per context) with an explicit layout in group 0, a buffer of each
    /// kind of `bindings` bound in order to bindings 0, 1, ..., and
    /// values for its `override` constants. One label names one source and layout.
    fn kernel(
        &self,
        label: &str,
        entry: &str,
        source: impl FnOnce() -> String,
        bindings: &[wgpu::BufferBindingType],
        constants: &[(&str, f64)],
    ) -> Result<Kernel, GpuError> {
        let key = format!("{label}:{entry}:{constants:?}");
        let mut kernels = self.kernels.lock().expect("pipeline cache");
        if let Some(kernel) = kernels.get(&key) {
            return Ok(kernel.clone());
        }
        let kernel = self.build_kernel(label, entry, &source(), bindings, constants)?;
        kernels.insert(key, kernel.clone());
        Ok(kernel)
    }

    fn build_kernel(
        &self,
        label: &str,
        entry: &str,
        source: &str,
        bindings: &[wgpu::BufferBindingType],
        constants: &[(&str, f64)],
    ) -> Result<Kernel, GpuError> {
        let entries: Vec<wgpu::BindGroupLayoutEntry> =
            (0u32..).zip(bindings).map(|(i, &ty)| buffer_entry(i, ty)).collect();
        self.scoped(|| {
            let module = self.device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            });
            let layout = self.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some(label),
                entries: &entries,
            });
            let pipeline_layout = self.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(label),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let pipeline = self.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(label),
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some(entry),
                compilation_options: wgpu::PipelineCompilationOptions {
                    constants,
                    ..Default::default()
                },
                cache: None,
            });
            Kernel { pipeline, layout }
        })
    }

    /// A bind group binding `buffers` whole, in order, to bindings 0, 1, ... of `layout`.
    fn bind_group(
        &self,
        label: &str,
        layout: &wgpu::BindGroupLayout,
        buffers: &[&wgpu::Buffer],
    ) -> Result<wgpu::BindGroup, GpuError> {
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource: b.as_entire_binding(),
            })
            .collect();
        self.scoped(|| {
            self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(label),
                layout,
                entries: &entries,
            })
        })
    }

    /// A buffer, with allocation failures reported as typed errors.
    /// A kernel's output buffer of `bytes` and the staging buffer it is read back through.
    fn output_and_staging(&self, label: &str, bytes: u64) -> Result<(wgpu::Buffer, wgpu::Buffer), GpuError> {
        let output = self.buffer(label, bytes, wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC)?;
        let staging = self.buffer(
            &format!("{label} staging"),
            bytes,
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        )?;
        Ok((output, staging))
    }

    fn buffer(&self, label: &str, size: u64, usage: wgpu::BufferUsages) -> Result<wgpu::Buffer, GpuError> {
        let max = self.limits.max_buffer_size;
        if size > max {
            return Err(GpuError::TooLarge(format!(
                "{label} needs {size} bytes, the adapter allows {max}"
            )));
        }
        self.scoped(|| {
            self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: size.max(16),
                usage,
                mapped_at_creation: false,
            })
        })
    }

    /// Dispatch grid for `invocations` threads of `workgroup_size`: (x, y, row width). Past
    /// the adapter's workgroups-per-dimension limit (65,535 on most) the grid becomes 2-D.
    fn grid(&self, invocations: u32, workgroup_size: u32) -> (u32, u32, u32) {
        let groups = invocations.div_ceil(workgroup_size).max(1);
        let max = self.limits.max_compute_workgroups_per_dimension.max(1);
        if groups <= max {
            (groups, 1, groups * workgroup_size)
        } else {
            (max, groups.div_ceil(max), max * workgroup_size)
        }
    }

    /// Runs `kernel` (binding 0 its input, read; binding 1 its output, written; one invocation
    /// per element, WORKGROUP_SIZE a workgroup) on the `count` elements of `input` and returns
    /// the `output_bytes` it wrote: the test kernels that compare a WGSL twin with the CPU's.
    fn map_elements(
        &self,
        label: &str,
        kernel: &Kernel,
        input: &[u8],
        count: u32,
        output_bytes: u64,
    ) -> Result<Vec<u8>, GpuError> {
        let input_buffer = self.buffer(
            label,
            input.len() as u64,
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        )?;
        let output = self.buffer(
            label,
            output_bytes,
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        )?;
        let staging = self.buffer(
            label,
            output_bytes,
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        )?;
        self.queue.write_buffer(&input_buffer, 0, input);
        let bind_group = self.bind_group(label, &kernel.layout, &[&input_buffer, &output])?;
        let mut encoder = self.encoder(label);
        let (x, y, _) = self.grid(count, WORKGROUP_SIZE);
        encode_dispatch(&mut encoder, label, &kernel.pipeline, &bind_group, (x, y));
        encoder.copy_buffer_to_buffer(&output, 0, &staging, 0, output_bytes);
        self.finish_and_read(encoder, &staging, output_bytes)
    }

    /// Submits `encoder`, waits, and copies the first `bytes` of `staging` out.
    fn finish_and_read(
        &self,
        encoder: wgpu::CommandEncoder,
        staging: &wgpu::Buffer,
        bytes: u64,
    ) -> Result<Vec<u8>, GpuError> {
        self.scoped(|| self.queue.submit([encoder.finish()]))?;
        let slice = staging.slice(..bytes);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        self.check_lost()?;
        rx.recv()
            .map_err(|e| GpuError::Readback(e.to_string()))?
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        let bytes = slice
            .get_mapped_range()
            .map_err(|e| GpuError::Readback(e.to_string()))?
            .to_vec();
        staging.unmap();
        Ok(bytes)
    }
}

use crate::prior::MAX_LAWS;

/// Host twin of `Prior` in shaders/shared/candidate.wgsl (its per-slot arrays of vec4 are
/// these flat arrays of [`MAX_LAWS`]). Keep in sync.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GpuPrior {
    key: [u32; 2],
    n_laws: u32,
    _pad0: u32,
    thresholds: [u32; MAX_LAWS],
    law_id: [u32; MAX_LAWS],
    n_params: [u32; MAX_LAWS],
    lower: [[f32; 4]; 2 * MAX_LAWS],
    upper: [[f32; 4]; 2 * MAX_LAWS],
}

impl GpuPrior {
    /// The uniform of `prior` and `seed`. Thresholds of all but the last slot are below 2³²
    /// (every weight is positive), so they fit u32 and compare as on the CPU.
    pub fn new(prior: &Prior, seed: u64) -> Self {
        let mut g = GpuPrior::zeroed();
        g.key = crate::rng::key_of_seed(seed);
        g.n_laws = prior.boxes.len() as u32;
        for (slot, b) in prior.boxes.iter().enumerate() {
            g.thresholds[slot] = prior.thresholds[slot].min(u64::from(u32::MAX)) as u32;
            g.law_id[slot] = b.law.index() as u32;
            g.n_params[slot] = b.lower.len() as u32;
            for j in 0..b.lower.len() {
                g.lower[2 * slot + j / 4][j % 4] = b.lower[j];
                g.upper[2 * slot + j / 4][j % 4] = b.upper[j];
            }
        }
        g
    }
}

/// Host twin of `Proposal` in shaders/shared/proposal.wgsl. Keep in sync.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub(crate) struct GpuProposal {
    pub law: u32,
    pub params: [f32; 6],
    pub _pad: u32,
}

impl GpuProposal {
    fn new(law: crate::laws::Law, params: [f32; 6]) -> Self {
        Self {
            law: law.index() as u32,
            params,
            _pad: 0,
        }
    }
}

/// Samples scored per dispatch: lavapipe ends loops once an invocation has run 65,535
/// iterations of all its loops together, and a dispatch may make four passes over its slice
/// (one per law; shaders/shared/ssr.wgsl), so longer records are scored in slices whose sums the
/// kernel adds up.
const SAMPLES_PER_DISPATCH: u32 = 32_768;

/// Candidates scored together by either scoring kernel: by one invocation
/// ([`Shape::Blocked`]) or one workgroup ([`Shape::Tiled`]); `CANDIDATES` in
/// shaders/shared/ssr.wgsl.
const CANDIDATES_PER_TILE: u32 = 16;

/// The data columns of the scoring kernels (bindings 2-4): bit speed, torque and weight-on-bit
/// ratio of `problem` in f32, padded to whole quads (w = 1 keeps every law finite; the kernels
/// mask the padding).
fn data_columns(problem: &Problem) -> [Vec<f32>; 3] {
    let len = 4 * problem.data_len().div_ceil(4);
    let column = |v: &[f64], pad: f32| {
        let mut c: Vec<f32> = v.iter().map(|&x| x as f32).collect();
        c.resize(len, pad);
        c
    };
    [
        column(&problem.speed_rad_s, 1.0),
        column(&problem.torque_nm, 0.0),
        column(&problem.wob_ratio, 0.0),
    ]
}

/// False when every sample has r = 1 (the paper's assumption): the kernels then skip the ratio
/// column (override HAS_RATIO).
fn has_ratio(problem: &Problem) -> bool {
    problem.wob_ratio.iter().any(|&r| r.to_bits() != 1.0f64.to_bits())
}

/// Candidates per scoring dispatch at most, for records of `d` samples: at most 2³² candidate ×
/// sample evaluations (seconds on a software driver, far below watchdog limits on hardware),
/// 4 M candidates and the binding limit; and of those, explicit ones (32 bytes each).
fn candidates_per_dispatch(d: usize, limits: &wgpu::Limits) -> (usize, usize) {
    let max_binding = limits.max_storage_buffer_binding_size;
    let chunk = ((1u64 << 32) / d.max(1) as u64)
        .clamp(1024, 1 << 22)
        .min(max_binding / 4) as usize;
    (chunk, chunk.min(1 << 20).min((max_binding / 32) as usize))
}

/// A scoring kernel bound to its buffers: its pipeline and bind group, the job's buffer and the
/// SSR buffers (bindings 1 and 5, and the buffer SSR is read back through).
struct ScoringBuffers<'a> {
    pipeline: &'a wgpu::ComputePipeline,
    bind_group: &'a wgpu::BindGroup,
    job: &'a wgpu::Buffer,
    ssr: &'a wgpu::Buffer,
    staging: &'a wgpu::Buffer,
}

/// Runs a scoring kernel (`buffers.pipeline`, entry point of `shape`) over the `out.len()`
/// candidates of `job` (its row width set here), over `data_len` samples in slices of
/// SAMPLES_PER_DISPATCH, each dispatch adding to the last, and reads back their SSR into `out`.
fn score_dispatch(
    ctx: &GpuContext,
    shape: Shape,
    buffers: &ScoringBuffers,
    job: Job,
    data_len: u32,
    out: &mut [f32],
) -> Result<(), GpuError> {
    let count = out.len() as u32;
    let tiles = count.div_ceil(CANDIDATES_PER_TILE);
    // Row width in invocations (blocked) or workgroups (tiled), as the entry point counts.
    let (x, y, row_width) = if shape.is_tiled() {
        ctx.grid(tiles, 1)
    } else {
        ctx.grid(tiles, WORKGROUP_SIZE)
    };
    debug_assert_eq!(job.count, count, "one sum per candidate of the job");
    let job = Job { row_width, ..job };
    let new_encoder = || {
        ctx.device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("scoring") })
    };
    let mut encoder = new_encoder();
    for s0 in (0..data_len).step_by(SAMPLES_PER_DISPATCH as usize) {
        let slice = job.samples(s0..(s0 + SAMPLES_PER_DISPATCH).min(data_len));
        ctx.queue.write_buffer(buffers.job, 0, bytemuck::bytes_of(&slice));
        encode_dispatch(&mut encoder, "scoring", buffers.pipeline, buffers.bind_group, (x, y));
        if s0 + SAMPLES_PER_DISPATCH < data_len {
            // The next slice rewrites the job: submit this one first.
            ctx.scoped(|| ctx.queue.submit([encoder.finish()]))?;
            encoder = new_encoder();
        }
    }
    let bytes = 4 * u64::from(count);
    encoder.copy_buffer_to_buffer(buffers.ssr, 0, buffers.staging, 0, bytes);
    let raw = ctx.finish_and_read(encoder, buffers.staging, bytes)?;
    out.copy_from_slice(bytemuck::cast_slice(&raw));
    Ok(())
}

/// Host twin of `Job` in shaders/shared/job.wgsl. Keep in sync.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct Job {
    start: [u32; 2],
    population: u32,
    count: u32,
    data_start: u32,
    data_end: u32,
    row_width: u32,
    accumulate: u32,
}

impl Job {
    fn new(population: u32, start: u64, count: u32, row_width: u32) -> Self {
        Self {
            start: [start as u32, (start >> 32) as u32],
            population,
            count,
            data_start: 0,
            data_end: 0,
            row_width,
            accumulate: 0,
        }
    }

    /// The same job restricted to samples `range`, adding to earlier dispatches unless first.
    fn samples(self, range: std::ops::Range<u32>) -> Self {
        Self {
            data_start: range.start,
            data_end: range.end,
            accumulate: u32::from(range.start > 0),
            ..self
        }
    }
}

/// Records one compute dispatch of `pipeline` with `bind_group` over a (x, y) grid.
fn encode_dispatch(
    encoder: &mut wgpu::CommandEncoder,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    bind_group: &wgpu::BindGroup,
    (x, y): (u32, u32),
) {
    let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
        label: Some(label),
        timestamp_writes: None,
    });
    pass.set_pipeline(pipeline);
    pass.set_bind_group(0, bind_group, &[]);
    pass.dispatch_workgroups(x, y, 1);
}

/// A bind-group-layout entry for a compute-visible buffer.
fn buffer_entry(binding: u32, ty: wgpu::BufferBindingType) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

const UNIFORM: wgpu::BufferBindingType = wgpu::BufferBindingType::Uniform;
const STORAGE_READ: wgpu::BufferBindingType = wgpu::BufferBindingType::Storage { read_only: true };
const STORAGE_WRITE: wgpu::BufferBindingType = wgpu::BufferBindingType::Storage { read_only: false };
/// The bindings a scoring kernel that reads its candidates from a buffer starts with: the
/// candidates (proposals, or the records' priors), the job, the speed, torque and ratio
/// columns, the sums of squares it writes. The job is a read-only storage buffer here, not a
/// uniform one: from a uniform job, lavapipe (Mesa 22.3) compiles the proposals' kernel again at
/// every dispatch (by its profile, inlining uniform values into the shader), 25 ms where
/// scoring the SMC's or the evidence's few hundred proposals takes one; the records' kernel
/// shares the layout. The streaming, kernel-sum and stability kernels keep uniform jobs: on
/// lavapipe their tests ran longer with storage ones (2026-12-01).
const STORED_CANDIDATE_BINDINGS: [wgpu::BufferBindingType; 6] = [
    STORAGE_READ,
    STORAGE_READ,
    STORAGE_READ,
    STORAGE_READ,
    STORAGE_READ,
    STORAGE_WRITE,
];

/// Invocations per workgroup of every kernel (`@workgroup_size(64)`).
const WORKGROUP_SIZE: u32 = 64;

#[cfg(test)]
mod build_tests {
    /// What build.rs validated is what a process without law files runs: the splice of no law
    /// files and build.rs's version of it agree.
    #[test]
    fn the_kernels_validated_at_build_time_are_the_ones_run() {
        let pairs = [
            (super::residual_source(), built_in_kernel!("residual")),
            (super::score_params_source(), built_in_kernel!("score_params")),
            (super::records_source(), built_in_kernel!("records")),
            (super::slopes_source(), built_in_kernel!("slopes")),
            (
                super::file_laws::splice(kernel!("kernel_sums"), &[]),
                built_in_kernel!("kernel_sums"),
            ),
            (
                super::file_laws::splice(kernel!("stability"), &[]),
                built_in_kernel!("stability"),
            ),
            (
                super::file_laws::splice(kernel!("candidates"), &[]),
                built_in_kernel!("candidates"),
            ),
        ];
        for (run, validated) in pairs {
            assert_eq!(run, validated);
        }
    }
}

#[cfg(test)]
mod adapter_tests {
    use super::*;

    #[test]
    fn opengl_is_used_only_where_named() {
        use wgpu::Backends;
        let unnamed = backends_named(None);
        assert!(
            unnamed.contains(Backends::VULKAN | Backends::METAL | Backends::DX12),
            "{unnamed:?}"
        );
        assert!(!unnamed.contains(Backends::GL), "{unnamed:?}");
        assert_eq!(backends_named(Some("gl")), Backends::GL);
        assert_eq!(backends_named(Some("vulkan,gl")), Backends::VULKAN | Backends::GL);
        assert_eq!(backends_named(Some("vulkan")), Backends::VULKAN);
    }

    fn adapter(name: &str, vendor: u32, bus: &str, backend: wgpu::Backend) -> wgpu::AdapterInfo {
        wgpu::AdapterInfo {
            name: name.into(),
            vendor,
            device_pci_bus_id: bus.into(),
            ..wgpu::AdapterInfo::new(wgpu::DeviceType::DiscreteGpu, backend)
        }
    }

    /// Two identical H100s (listed out of bus order, one also through GL) and lavapipe.
    fn machine() -> Vec<wgpu::AdapterInfo> {
        use wgpu::Backend::{Gl, Vulkan};
        let mut lavapipe = adapter("llvmpipe", 0x10005, "", Vulkan);
        lavapipe.device_type = wgpu::DeviceType::Cpu;
        vec![
            adapter("NVIDIA H100", NVIDIA, "0000:c1:00.0", Vulkan),
            adapter("NVIDIA H100", NVIDIA, "0000:3b:00.0", Gl),
            lavapipe,
            adapter("NVIDIA H100", NVIDIA, "0000:3b:00.0", Vulkan),
        ]
    }

    fn wish(pairs: &[(&str, &str)]) -> Result<AdapterWish, GpuError> {
        AdapterWish::from_env(|name| pairs.iter().find(|p| p.0 == name).map(|p| p.1.to_string()))
    }

    #[test]
    fn the_environment_names_one_of_two_identical_gpus() {
        let m = machine();
        // CUDA ordinals count NVIDIA GPUs in PCI bus order, whatever order wgpu lists them in,
        // and take a device's adapter not through OpenGL.
        let cuda = |v: &str| wish(&[("CUDA_VISIBLE_DEVICES", v)]).unwrap();
        assert_eq!(cuda("0,1").pick(&m).unwrap(), Some(3));
        assert_eq!(cuda("1").pick(&m).unwrap(), Some(0));
        assert_eq!(cuda("1,0").pick_all(&m).unwrap(), Some(vec![0, 3]));
        assert!(matches!(cuda("2").pick(&m), Err(GpuError::NotNamed(_))));
        // No GPU given to the job: no adapter (auto falls back to the CPU).
        for hidden in ["", "-1", " "] {
            assert_eq!(cuda(hidden), AdapterWish::NoneVisible);
            assert!(matches!(cuda(hidden).pick(&m), Err(GpuError::NotNamed(_))));
        }
        // A UUID is not something wgpu reports: wgpu chooses.
        assert_eq!(cuda("GPU-5a3c"), AdapterWish::Any);
        // BITROCK_ADAPTER wins over the others: an index, or a bus id with or without domain.
        let both = [("BITROCK_ADAPTER", "2"), ("CUDA_VISIBLE_DEVICES", "0")];
        assert_eq!(wish(&both).unwrap().pick(&m).unwrap(), Some(2));
        assert_eq!(wish(&both).unwrap().pick_all(&m).unwrap(), Some(vec![2]));
        assert_eq!(
            wish(&[("BITROCK_ADAPTER", "C1:00.0")]).unwrap().pick(&m).unwrap(),
            Some(0)
        );
        assert_eq!(
            wish(&[("BITROCK_ADAPTER", "0000:3b:00.0")]).unwrap().pick(&m).unwrap(),
            Some(1)
        );
        assert!(
            matches!(wish(&[("BITROCK_ADAPTER", "4")]).unwrap().pick(&m), Err(GpuError::NotNamed(m)) if m.contains("4 adapters"))
        );
        assert!(matches!(
            wish(&[("BITROCK_ADAPTER", "fast")]),
            Err(GpuError::Setting { name: ADAPTER_VAR, .. })
        ));
        assert_eq!(
            wish(&[("WGPU_ADAPTER_NAME", "llvm")]).unwrap().pick(&m).unwrap(),
            Some(2)
        );
        assert_eq!(wish(&[]).unwrap().pick(&m).unwrap(), None);
        // Every GPU once, not through OpenGL where it can be avoided; no CPU driver.
        assert_eq!(every_gpu(&m), vec![0, 3]);
    }

    #[test]
    fn cuda_visible_devices_says_nothing_where_wgpu_sees_no_nvidia_adapter() {
        let lavapipe_only = vec![machine()[2].clone()];
        for v in ["0", "", "-1", "1,0"] {
            let w = wish(&[("CUDA_VISIBLE_DEVICES", v)]).unwrap();
            assert_eq!(w.pick(&lavapipe_only).unwrap(), None, "{v:?}");
            assert_eq!(w.pick_all(&lavapipe_only).unwrap(), None, "{v:?}");
        }
        assert!(every_gpu(&lavapipe_only).is_empty());
    }
}
