//! What a Vulkan driver's compiler makes of a WGSL module's compute kernels: the statistics it
//! reports through `VK_KHR_pipeline_executable_properties` (registers, spills, scratch memory,
//! instructions, code size: each driver names its own), one kernel at a time.
//!
//! Lavapipe compiles for the CPU's SIMD units and reports nothing; a GPU's driver does (NVIDIA's:
//! register count and code size; AMD's RADV: VGPRs, SGPRs, spills, scratch, instructions and more).
//! RADV also compiles without an AMD GPU: with `RADV_FORCE_FAMILY=navi21` (any family it knows) it
//! lists a "Null hardware" device that creates pipelines and runs nothing, so the 2-core machine
//! without a GPU can read what a GPU compiler makes of the physics kernel (`dextrain bench
//! --shader-stats`, docs/gpu.md). wgpu cannot open that device, so this talks to Vulkan through
//! `ash` (the bindings wgpu itself uses) and writes the SPIR-V with naga as wgpu does.

use anyhow::{anyhow, bail, Context, Result};
use ash::vk;
use std::ffi::{CStr, CString};

/// The Vulkan extension that reports the statistics.
const STATS_EXTENSION: &CStr = c"VK_KHR_pipeline_executable_properties";

/// One statistic as the driver typed it.
#[derive(Clone, Debug, PartialEq)]
pub enum StatValue {
    /// A yes/no statistic.
    Bool(bool),
    /// A signed count.
    Int(i64),
    /// An unsigned count.
    UInt(u64),
    /// A ratio or a time.
    Float(f64),
}

impl StatValue {
    /// The value as a JSON number (a bool as 0 or 1).
    pub fn to_json(&self) -> serde_json::Value {
        match *self {
            StatValue::Bool(b) => serde_json::json!(b as u8),
            StatValue::Int(v) => serde_json::json!(v),
            StatValue::UInt(v) => serde_json::json!(v),
            StatValue::Float(v) => serde_json::json!(v),
        }
    }
}

/// One executable of a kernel's pipeline (a driver may make more than one of a pipeline) and its
/// statistics, in the driver's order.
#[derive(Clone, Debug, PartialEq)]
pub struct ExecutableStats {
    /// The driver's name for the executable (e.g. "Compute Shader").
    pub name: String,
    /// (the driver's name of the statistic, its value).
    pub stats: Vec<(String, StatValue)>,
}

/// One compute entry point of the module compiled into a pipeline.
#[derive(Clone, Debug, PartialEq)]
pub struct KernelStats {
    /// The WGSL entry point.
    pub entry_point: String,
    /// Wall time of the driver's compile (vkCreateComputePipelines), seconds.
    pub compile_s: f64,
    /// The pipeline's executables.
    pub executables: Vec<ExecutableStats>,
}

/// Every compute kernel of a module, compiled on one Vulkan device.
#[derive(Clone, Debug, PartialEq)]
pub struct ModuleStats {
    /// The Vulkan device's name (e.g. "NVIDIA H200", "Null hardware (RADV NAVI21)").
    pub adapter: String,
    /// The driver's name and version as it reports them (e.g. "radv, Mesa 22.3.6"); empty for a
    /// device older than Vulkan 1.2.
    pub driver: String,
    /// The kernels in the module's order of entry points.
    pub kernels: Vec<KernelStats>,
}

impl ModuleStats {
    /// `{"adapter": …, "driver": …, "kernels": [{"entry_point", "compile_s", "executable", "stats": {name: value}}]}`
    /// (the first executable of each kernel; the others under "other_executables").
    pub fn to_json(&self) -> serde_json::Value {
        let exec_json = |e: &ExecutableStats| {
            let mut stats = serde_json::Map::new();
            for (n, v) in &e.stats {
                stats.insert(n.clone(), v.to_json());
            }
            (e.name.clone(), serde_json::Value::Object(stats))
        };
        let kernels: Vec<serde_json::Value> = self
            .kernels
            .iter()
            .map(|k| {
                let mut o = serde_json::json!({ "entry_point": k.entry_point, "compile_s": k.compile_s });
                if let Some(first) = k.executables.first() {
                    let (name, stats) = exec_json(first);
                    o["executable"] = serde_json::Value::String(name);
                    o["stats"] = stats;
                }
                if k.executables.len() > 1 {
                    o["other_executables"] = k.executables[1..].iter().map(|e| serde_json::json!(exec_json(e))).collect();
                }
                o
            })
            .collect();
        serde_json::json!({ "adapter": self.adapter, "driver": self.driver, "kernels": kernels })
    }
}

/// A storage or uniform buffer binding the pipeline layout must declare.
struct BufferBinding {
    group: u32,
    binding: u32,
    uniform: bool,
}

/// The SPIR-V of each compute entry point of the WGSL module `source` that `wanted` accepts
/// (`label` names the module in errors), written as wgpu writes it for a Vulkan device without
/// robust buffer access 2 (SPIR-V 1.3, array and buffer indices clamped, loops bounded), and the
/// module's buffer bindings.
fn spirv_kernels(source: &str, label: &str, wanted: &dyn Fn(&str) -> bool) -> Result<(Vec<(String, Vec<u32>)>, Vec<BufferBinding>)> {
    // naga's report's first line, without its own "error: "
    let first_line = |report: String| report.lines().next().unwrap_or_default().trim_start_matches("error: ").to_string();
    let module = naga::front::wgsl::parse_str(source).map_err(|e| anyhow!("{label}: not valid WGSL: {}", first_line(e.emit_to_string(source))))?;
    let info = naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
        .validate(&module)
        .map_err(|e| anyhow!("{label}: the WGSL does not validate: {}", first_line(e.emit_to_string(source))))?;
    let mut bindings = Vec::new();
    for (_, var) in module.global_variables.iter() {
        let Some(rb) = &var.binding else { continue };
        let uniform = match var.space {
            naga::AddressSpace::Uniform => true,
            naga::AddressSpace::Storage { .. } => false,
            other => bail!("{label}: binding @group({}) @binding({}) is in address space {other:?}; expected a uniform or storage buffer", rb.group, rb.binding),
        };
        bindings.push(BufferBinding { group: rb.group, binding: rb.binding, uniform });
    }
    let options = naga::back::spv::Options {
        lang_version: (1, 3),
        bounds_check_policies: naga::proc::BoundsCheckPolicies {
            index: naga::proc::BoundsCheckPolicy::Restrict,
            buffer: naga::proc::BoundsCheckPolicy::Restrict,
            image_load: naga::proc::BoundsCheckPolicy::Restrict,
            binding_array: naga::proc::BoundsCheckPolicy::Unchecked,
        },
        ..Default::default()
    };
    let mut kernels = Vec::new();
    for ep in module.entry_points.iter().filter(|ep| ep.stage == naga::ShaderStage::Compute && wanted(&ep.name)) {
        let pipeline = naga::back::spv::PipelineOptions { shader_stage: naga::ShaderStage::Compute, entry_point: ep.name.clone() };
        let words = naga::back::spv::write_vec(&module, &info, &options, Some(&pipeline)).map_err(|e| anyhow!("{label}: cannot write SPIR-V for entry point {}: {e}", ep.name))?;
        kernels.push((ep.name.clone(), words));
    }
    if kernels.is_empty() {
        bail!("{label}: no compute entry point to compile");
    }
    Ok((kernels, bindings))
}

/// A driver's fixed-size name field as text ("" where it holds no NUL).
fn c_text(c: Result<&CStr, std::ffi::FromBytesUntilNulError>) -> String {
    c.map(|c| c.to_string_lossy().into_owned()).unwrap_or_default()
}

/// The Vulkan objects, destroyed in reverse order however the work ends.
struct Vulkan {
    _entry: ash::Entry,
    instance: ash::Instance,
    device: Option<ash::Device>,
}

impl Drop for Vulkan {
    fn drop(&mut self) {
        // SAFETY: every object made from the device is destroyed before it (compile_kernel), and
        // the device before the instance that made it.
        unsafe {
            if let Some(d) = self.device.take() {
                d.destroy_device(None);
            }
            self.instance.destroy_instance(None);
        }
    }
}

/// Compiles the compute entry points of the WGSL module `source` that `wanted` accepts on a Vulkan
/// device and returns the driver's statistics. `adapter`: a device whose name contains it
/// (case-insensitive); None: the first device that reports statistics. `label` names the module
/// in errors. An error names
/// the module or the device and says what was expected (a device without the extension: which
/// devices there are, and that RADV_FORCE_FAMILY gives RADV's compiler without an AMD GPU).
pub fn compile_stats(source: &str, label: &str, adapter: Option<&str>, wanted: &dyn Fn(&str) -> bool) -> Result<ModuleStats> {
    let (kernels, bindings) = spirv_kernels(source, label, wanted)?;
    // SAFETY: plain Vulkan calls on objects this function creates and destroys (Vulkan's Drop);
    // every create-info outlives the call that reads it.
    unsafe {
        let entry = ash::Entry::load().map_err(|e| anyhow!("shader statistics: cannot load the Vulkan loader libvulkan.so.1 ({e}); install libvulkan1"))?;
        let app = vk::ApplicationInfo::default().application_name(c"dextrain").api_version(vk::API_VERSION_1_1);
        let instance = entry.create_instance(&vk::InstanceCreateInfo::default().application_info(&app), None).context("shader statistics: cannot create a Vulkan instance")?;
        let mut vulkan = Vulkan { _entry: entry, instance, device: None };
        let physical = vulkan.instance.enumerate_physical_devices().context("shader statistics: cannot list the Vulkan devices")?;
        let mut listed = Vec::new();
        let mut chosen = None;
        for pd in physical {
            let props = vulkan.instance.get_physical_device_properties(pd);
            let name = c_text(props.device_name_as_c_str());
            let has_stats = vulkan
                .instance
                .enumerate_device_extension_properties(pd)
                .map(|exts| exts.iter().any(|e| e.extension_name_as_c_str() == Ok(STATS_EXTENSION)))
                .unwrap_or(false);
            let named = adapter.is_none_or(|a| name.to_lowercase().contains(&a.to_lowercase()));
            listed.push(format!("{name} ({})", if has_stats { "reports statistics" } else { "no statistics" }));
            if chosen.is_none() && named && (has_stats || adapter.is_some()) {
                chosen = Some((pd, name, has_stats, props.api_version));
            }
        }
        let devices = if listed.is_empty() { "none".to_string() } else { listed.join(", ") };
        let hint = "RADV_FORCE_FAMILY=navi21 lists RADV's compiler without an AMD GPU";
        let (pd, name, has_stats, api_version) = match (chosen, adapter) {
            (Some(c), _) => c,
            (None, Some(a)) => bail!("shader statistics: no Vulkan device named like '{a}' (devices: {devices}); {hint}"),
            (None, None) => bail!("shader statistics: no Vulkan device reports pipeline statistics (VK_KHR_pipeline_executable_properties; devices: {devices}); {hint}"),
        };
        // the driver and its version (VkPhysicalDeviceDriverProperties: Vulkan 1.2)
        let mut driver = String::new();
        if vk::api_version_minor(api_version) >= 2 {
            let mut dp = vk::PhysicalDeviceDriverProperties::default();
            let mut p2 = vk::PhysicalDeviceProperties2::default().push_next(&mut dp);
            vulkan.instance.get_physical_device_properties2(pd, &mut p2);
            driver = format!("{}, {}", c_text(dp.driver_name_as_c_str()), c_text(dp.driver_info_as_c_str()));
        }
        if !has_stats {
            bail!("shader statistics: the Vulkan device {name} does not report pipeline statistics (VK_KHR_pipeline_executable_properties; devices: {devices}); {hint}");
        }
        let family = vulkan
            .instance
            .get_physical_device_queue_family_properties(pd)
            .iter()
            .position(|q| q.queue_flags.contains(vk::QueueFlags::COMPUTE))
            .ok_or_else(|| anyhow!("shader statistics: the Vulkan device {name} has no compute queue"))? as u32;
        let priority = [1.0f32];
        let queues = [vk::DeviceQueueCreateInfo::default().queue_family_index(family).queue_priorities(&priority)];
        let extensions = [STATS_EXTENSION.as_ptr()];
        let mut feature = vk::PhysicalDevicePipelineExecutablePropertiesFeaturesKHR::default().pipeline_executable_info(true);
        let info = vk::DeviceCreateInfo::default().queue_create_infos(&queues).enabled_extension_names(&extensions).push_next(&mut feature);
        let device = vulkan.instance.create_device(pd, &info, None).with_context(|| format!("shader statistics: cannot open the Vulkan device {name}"))?;
        vulkan.device = Some(device.clone());
        let props_fn = ash::khr::pipeline_executable_properties::Device::new(&vulkan.instance, &device);
        let mut out = Vec::new();
        for (entry_point, words) in &kernels {
            let k = compile_kernel(&device, &props_fn, entry_point, words, &bindings).with_context(|| format!("shader statistics: {label}, entry point {entry_point}, on {name}"))?;
            out.push(k);
        }
        Ok(ModuleStats { adapter: name, driver, kernels: out })
    }
}

/// One kernel's Vulkan objects, destroyed (those made so far) however compile_kernel ends.
struct KernelObjects<'d> {
    device: &'d ash::Device,
    module: vk::ShaderModule,
    set_layouts: Vec<vk::DescriptorSetLayout>,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
}

impl Drop for KernelObjects<'_> {
    fn drop(&mut self) {
        // SAFETY: each handle was made on `device` (a null handle is ignored by the destroy calls),
        // and nothing uses them after compile_kernel.
        unsafe {
            self.device.destroy_pipeline(self.pipeline, None);
            self.device.destroy_pipeline_layout(self.layout, None);
            self.set_layouts.iter().for_each(|l| self.device.destroy_descriptor_set_layout(*l, None));
            self.device.destroy_shader_module(self.module, None);
        }
    }
}

/// One kernel's pipeline on `device`: its layout from `bindings`, compiled with the statistics
/// captured, read, and every object destroyed again.
unsafe fn compile_kernel(device: &ash::Device, props_fn: &ash::khr::pipeline_executable_properties::Device, entry_point: &str, words: &[u32], bindings: &[BufferBinding]) -> Result<KernelStats> {
    let name = CString::new(entry_point).context("the entry point's name holds a NUL")?;
    let mut objects = KernelObjects { device, module: vk::ShaderModule::null(), set_layouts: Vec::new(), layout: vk::PipelineLayout::null(), pipeline: vk::Pipeline::null() };
    // SAFETY (the whole body): plain Vulkan calls; what they make is destroyed by `objects`.
    unsafe {
        objects.module = device.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(words), None).context("cannot create the shader module")?;
        let groups = bindings.iter().map(|b| b.group + 1).max().unwrap_or(0);
        for g in 0..groups {
            let entries: Vec<vk::DescriptorSetLayoutBinding> = bindings
                .iter()
                .filter(|b| b.group == g)
                .map(|b| {
                    let ty = if b.uniform { vk::DescriptorType::UNIFORM_BUFFER } else { vk::DescriptorType::STORAGE_BUFFER };
                    vk::DescriptorSetLayoutBinding::default().binding(b.binding).descriptor_type(ty).descriptor_count(1).stage_flags(vk::ShaderStageFlags::COMPUTE)
                })
                .collect();
            let l = device.create_descriptor_set_layout(&vk::DescriptorSetLayoutCreateInfo::default().bindings(&entries), None).with_context(|| format!("cannot create the descriptor set layout of group {g}"))?;
            objects.set_layouts.push(l);
        }
        objects.layout = device.create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default().set_layouts(&objects.set_layouts), None).context("cannot create the pipeline layout")?;
        let stage = vk::PipelineShaderStageCreateInfo::default().stage(vk::ShaderStageFlags::COMPUTE).module(objects.module).name(&name);
        let create = [vk::ComputePipelineCreateInfo::default().stage(stage).layout(objects.layout).flags(vk::PipelineCreateFlags::CAPTURE_STATISTICS_KHR)];
        let t0 = std::time::Instant::now();
        objects.pipeline = device.create_compute_pipelines(vk::PipelineCache::null(), &create, None).map_err(|(_, e)| anyhow!("the driver did not compile it: {e}"))?[0];
        let compile_s = t0.elapsed().as_secs_f64();
        let pipeline = objects.pipeline;
        let execs = props_fn.get_pipeline_executable_properties(&vk::PipelineInfoKHR::default().pipeline(pipeline)).context("cannot list the pipeline's executables")?;
        let mut executables = Vec::new();
        for (i, e) in execs.iter().enumerate() {
            let info = vk::PipelineExecutableInfoKHR::default().pipeline(pipeline).executable_index(i as u32);
            let stats = props_fn.get_pipeline_executable_statistics(&info).context("cannot read the executable's statistics")?;
            let stats = stats
                .iter()
                .map(|s| {
                    let v = match s.format {
                        vk::PipelineExecutableStatisticFormatKHR::BOOL32 => StatValue::Bool(s.value.b32 != 0),
                        vk::PipelineExecutableStatisticFormatKHR::INT64 => StatValue::Int(s.value.i64),
                        vk::PipelineExecutableStatisticFormatKHR::UINT64 => StatValue::UInt(s.value.u64),
                        _ => StatValue::Float(s.value.f64),
                    };
                    (c_text(s.name_as_c_str()), v)
                })
                .collect();
            executables.push(ExecutableStats { name: c_text(e.name_as_c_str()), stats });
        }
        Ok(KernelStats { entry_point: entry_point.to_string(), compile_s, executables })
    }
}
