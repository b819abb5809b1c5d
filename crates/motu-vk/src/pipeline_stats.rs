//! The driver's own statistics of a pipeline's executables (`VK_KHR_pipeline_executable_properties`):
//! registers, spills, private memory, instruction counts, whatever the driver reports per
//! compiled shader. Captured only when the context was opened with
//! [`crate::ContextOptions::pipeline_stats`] and the device has the extension's
//! `pipelineExecutableInfo` feature: pipelines are then created with
//! `VK_PIPELINE_CREATE_CAPTURE_STATISTICS_BIT_KHR`, read right after creation, logged at `info`
//! (one line per executable) and kept in the context's log ([`crate::Context::captured_pipelines`]).

use std::sync::Mutex;

use ash::vk;

/// One statistic's value, in the format the driver gave it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum StatisticValue {
    Bool(bool),
    I64(i64),
    U64(u64),
    F64(f64),
}

impl StatisticValue {
    /// The format's name: `bool`, `i64`, `u64` or `f64`.
    pub fn format(&self) -> &'static str {
        match self {
            StatisticValue::Bool(_) => "bool",
            StatisticValue::I64(_) => "i64",
            StatisticValue::U64(_) => "u64",
            StatisticValue::F64(_) => "f64",
        }
    }
}

impl std::fmt::Display for StatisticValue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StatisticValue::Bool(v) => write!(f, "{v}"),
            StatisticValue::I64(v) => write!(f, "{v}"),
            StatisticValue::U64(v) => write!(f, "{v}"),
            StatisticValue::F64(v) => write!(f, "{v}"),
        }
    }
}

/// One statistic of an executable (e.g. NVIDIA's register count, Mesa's spill count).
#[derive(Clone, Debug, PartialEq)]
pub struct PipelineStatistic {
    pub name: String,
    pub description: String,
    pub value: StatisticValue,
}

/// One internal representation of an executable as the driver gives it (e.g. an IR or a
/// disassembly with its code size): text (without the terminating NUL) or opaque bytes.
#[derive(Clone, Debug, PartialEq)]
pub struct InternalRepresentation {
    pub name: String,
    pub description: String,
    pub is_text: bool,
    pub data: Vec<u8>,
}

impl InternalRepresentation {
    /// The text of a text representation (lossy UTF-8), `None` for binary data.
    pub fn text(&self) -> Option<String> {
        self.is_text
            .then(|| String::from_utf8_lossy(&self.data).into_owned())
    }
}

/// One compiled executable of a pipeline (a shader stage, or several the driver merged).
#[derive(Clone, Debug, PartialEq)]
pub struct PipelineExecutable {
    pub name: String,
    pub description: String,
    /// The stages it runs (`raygen`, `any_hit`, `compute`, …).
    pub stages: Vec<&'static str>,
    pub subgroup_size: u32,
    pub statistics: Vec<PipelineStatistic>,
    /// What the driver offers beyond the statistics (often none).
    pub internal_representations: Vec<InternalRepresentation>,
}

/// Every executable of one pipeline with its statistics.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PipelineExecutableStats {
    pub executables: Vec<PipelineExecutable>,
}

/// A pipeline made while statistics were asked for: its label, its kind (`ray_tracing` or
/// `compute`) and its statistics (`None` where the device cannot capture them).
#[derive(Clone, Debug, PartialEq)]
pub struct CapturedPipeline {
    pub label: String,
    pub kind: &'static str,
    /// A ray-tracing pipeline's raygen stack (`vkGetRayTracingShaderGroupStackSizeKHR`, core
    /// to the extension, so known without the statistics): what lives across its traces.
    pub raygen_stack_bytes: Option<u64>,
    pub stats: Option<PipelineExecutableStats>,
}

/// The context's part: whether statistics were asked for, the extension's functions when they
/// can be captured, and the log of pipelines made.
pub(crate) struct PipelineStatsState {
    pub(crate) requested: bool,
    pub(crate) loader: Option<ash::khr::pipeline_executable_properties::Device>,
    pub(crate) log: Mutex<Vec<CapturedPipeline>>,
}

impl PipelineStatsState {
    pub(crate) fn off() -> Self {
        Self {
            requested: false,
            loader: None,
            log: Mutex::new(Vec::new()),
        }
    }

    /// The creation flags to add: capture statistics and internal representations when they
    /// can be read.
    fn create_flags(&self) -> vk::PipelineCreateFlags {
        if self.loader.is_some() {
            vk::PipelineCreateFlags::CAPTURE_STATISTICS_KHR
                | vk::PipelineCreateFlags::CAPTURE_INTERNAL_REPRESENTATIONS_KHR
        } else {
            vk::PipelineCreateFlags::empty()
        }
    }

    /// Creates a pipeline with `create(flags)`: with the capture flags when statistics can be
    /// read, and again without them should that fail (the diagnostic never fails a render).
    /// Returns the result and whether the pipeline captures.
    pub(crate) fn create<T, E: std::fmt::Debug>(
        &self,
        label: &str,
        create: impl Fn(vk::PipelineCreateFlags) -> Result<T, E>,
    ) -> (Result<T, E>, bool) {
        let flags = self.create_flags();
        let result = create(flags);
        match result {
            Err(e) if !flags.is_empty() => {
                tracing::warn!(
                    label,
                    error = ?e,
                    "creating the pipeline capturing statistics failed: made without them"
                );
                (create(vk::PipelineCreateFlags::empty()), false)
            }
            r => (r, !flags.is_empty()),
        }
    }

    /// After creating a pipeline through [`Self::create`]: its statistics (`pipeline`: it,
    /// when it captures), logged and kept in the log. `None` when not asked for (nothing
    /// logged), or asked for on a device without the extension (then logged with no
    /// statistics).
    pub(crate) fn capture(
        &self,
        pipeline: Option<vk::Pipeline>,
        label: &str,
        kind: &'static str,
        raygen_stack_bytes: Option<u64>,
    ) -> Option<PipelineExecutableStats> {
        if !self.requested {
            return None;
        }
        let stats = self
            .loader
            .as_ref()
            .zip(pipeline)
            .and_then(|(l, pipeline)| {
                read(l, pipeline)
                    .map_err(
                        |e| tracing::warn!(label, error = %e, "reading pipeline statistics failed"),
                    )
                    .ok()
            });
        if let Some(bytes) = raygen_stack_bytes {
            tracing::info!(
                pipeline = label,
                raygen_stack_bytes = bytes,
                "pipeline stack"
            );
        }
        if let Some(s) = &stats {
            for e in &s.executables {
                tracing::info!(
                    pipeline = label,
                    executable = %e.name,
                    stages = %e.stages.join("|"),
                    subgroup_size = e.subgroup_size,
                    statistics = %statistics_line(&e.statistics),
                    internal_representations = %e
                        .internal_representations
                        .iter()
                        .map(|r| format!("{} ({} bytes)", r.name, r.data.len()))
                        .collect::<Vec<_>>()
                        .join(", "),
                    "pipeline executable"
                );
            }
        }
        self.log
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(CapturedPipeline {
                label: label.to_string(),
                kind,
                raygen_stack_bytes,
                stats: stats.clone(),
            });
        stats
    }
}

/// `name=value` pairs of `stats`, comma-separated (one log line an executable).
pub(crate) fn statistics_line(stats: &[PipelineStatistic]) -> String {
    stats
        .iter()
        .map(|s| format!("{}={}", s.name, s.value))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Every executable of `pipeline` (created with `CAPTURE_STATISTICS`) and its statistics.
fn read(
    loader: &ash::khr::pipeline_executable_properties::Device,
    pipeline: vk::Pipeline,
) -> Result<PipelineExecutableStats, vk::Result> {
    let info = vk::PipelineInfoKHR::default().pipeline(pipeline);
    // SAFETY: the pipeline is live and was created with CAPTURE_STATISTICS on a device with
    // pipelineExecutableInfo enabled.
    let props = unsafe { loader.get_pipeline_executable_properties(&info) }?;
    let mut executables = Vec::with_capacity(props.len());
    for (i, p) in props.iter().enumerate() {
        let exe = vk::PipelineExecutableInfoKHR::default()
            .pipeline(pipeline)
            .executable_index(i as u32);
        // SAFETY: `i` is below the executable count just returned for this live pipeline.
        let stats = unsafe { loader.get_pipeline_executable_statistics(&exe) }?;
        // Internal representations are extra: a driver that fails them still gives statistics.
        let internal_representations = internal_representations(loader, &exe)
            .map_err(|e| tracing::warn!(error = %e, "reading internal representations failed"))
            .unwrap_or_default();
        executables.push(PipelineExecutable {
            name: c_text(p.name_as_c_str()),
            description: c_text(p.description_as_c_str()),
            stages: stage_names(p.stages),
            subgroup_size: p.subgroup_size,
            statistics: stats.iter().map(statistic).collect(),
            internal_representations,
        });
    }
    Ok(PipelineExecutableStats { executables })
}

/// The executable's internal representations: their sizes first, then their data.
fn internal_representations(
    loader: &ash::khr::pipeline_executable_properties::Device,
    exe: &vk::PipelineExecutableInfoKHR<'_>,
) -> Result<Vec<InternalRepresentation>, vk::Result> {
    // SAFETY: `exe` names an executable of a live pipeline created with
    // CAPTURE_INTERNAL_REPRESENTATIONS; with null data pointers only sizes are written.
    let mut reps = unsafe { loader.get_pipeline_executable_internal_representations(exe) }?;
    if reps.is_empty() {
        return Ok(Vec::new());
    }
    let mut data: Vec<Vec<u8>> = reps.iter().map(|r| vec![0u8; r.data_size]).collect();
    for (r, d) in reps.iter_mut().zip(&mut data) {
        r.p_data = d.as_mut_ptr().cast();
    }
    let mut count = reps.len() as u32;
    // SAFETY: `reps` holds `count` structs each pointing to `data_size` writable bytes that
    // outlive the call; the driver writes at most that much and updates `data_size`.
    let result = unsafe {
        (loader
            .fp()
            .get_pipeline_executable_internal_representations_khr)(
            loader.device(),
            exe,
            &mut count,
            reps.as_mut_ptr(),
        )
    };
    if result != vk::Result::SUCCESS && result != vk::Result::INCOMPLETE {
        return Err(result);
    }
    Ok(reps
        .iter()
        .zip(data)
        .take(count as usize)
        .map(|(r, d)| representation(r, d))
        .collect())
}

/// One representation from the driver's struct and the bytes read into its buffer: the
/// `data_size` written, less a text's NUL terminator.
pub(crate) fn representation(
    r: &vk::PipelineExecutableInternalRepresentationKHR<'_>,
    mut data: Vec<u8>,
) -> InternalRepresentation {
    data.truncate(r.data_size);
    let is_text = r.is_text == vk::TRUE;
    if is_text {
        while data.last() == Some(&0) {
            data.pop();
        }
    }
    InternalRepresentation {
        name: c_text(r.name_as_c_str()),
        description: c_text(r.description_as_c_str()),
        is_text,
        data,
    }
}

fn c_text(r: Result<&std::ffi::CStr, std::ffi::FromBytesUntilNulError>) -> String {
    r.map(|s| s.to_string_lossy().trim().to_string())
        .unwrap_or_default()
}

/// One driver statistic as a typed value.
pub(crate) fn statistic(s: &vk::PipelineExecutableStatisticKHR<'_>) -> PipelineStatistic {
    let v = s.value;
    // SAFETY: the union's member is the one `format` names (an unknown format reads as u64,
    // every member being 8 bytes or less of plain data).
    let value = unsafe {
        match s.format {
            vk::PipelineExecutableStatisticFormatKHR::BOOL32 => StatisticValue::Bool(v.b32 != 0),
            vk::PipelineExecutableStatisticFormatKHR::INT64 => StatisticValue::I64(v.i64),
            vk::PipelineExecutableStatisticFormatKHR::FLOAT64 => StatisticValue::F64(v.f64),
            _ => StatisticValue::U64(v.u64),
        }
    };
    PipelineStatistic {
        name: c_text(s.name_as_c_str()),
        description: c_text(s.description_as_c_str()),
        value,
    }
}

/// The names of the stages in `flags`.
pub(crate) fn stage_names(flags: vk::ShaderStageFlags) -> Vec<&'static str> {
    use vk::ShaderStageFlags as S;
    let names = [
        (S::VERTEX, "vertex"),
        (S::TESSELLATION_CONTROL, "tessellation_control"),
        (S::TESSELLATION_EVALUATION, "tessellation_evaluation"),
        (S::GEOMETRY, "geometry"),
        (S::FRAGMENT, "fragment"),
        (S::COMPUTE, "compute"),
        (S::RAYGEN_KHR, "raygen"),
        (S::ANY_HIT_KHR, "any_hit"),
        (S::CLOSEST_HIT_KHR, "closest_hit"),
        (S::MISS_KHR, "miss"),
        (S::INTERSECTION_KHR, "intersection"),
        (S::CALLABLE_KHR, "callable"),
        (S::TASK_EXT, "task"),
        (S::MESH_EXT, "mesh"),
    ];
    let mut out: Vec<&'static str> = names
        .iter()
        .filter(|(f, _)| flags.contains(*f))
        .map(|&(_, n)| n)
        .collect();
    let known = names.iter().fold(S::empty(), |a, (f, _)| a | *f);
    if !(flags & !known).is_empty() {
        out.push("other");
    }
    out
}

#[cfg(test)]
mod tests;
