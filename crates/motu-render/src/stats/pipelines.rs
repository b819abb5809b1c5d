//! `--pipeline-stats`: the driver's statistics of every pipeline the render made
//! (`motu_gpu::CapturedPipeline`), one entry a pipeline in creation order.

use serde::Serialize;

use super::mirror::{mirror, Mirror};

/// One pipeline: its label (`trace full`, `trace streamed`, a compute pass's name), its kind
/// (`ray_tracing` or `compute`) and its executables (`null` where the device lacks
/// `VK_KHR_pipeline_executable_properties`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PipelineStats {
    pub label: String,
    pub kind: &'static str,
    /// A ray-tracing pipeline's raygen stack (what stays live across its traces); `null` for
    /// compute pipelines.
    pub raygen_stack_bytes: Option<u64>,
    pub executables: Option<Vec<ExecutableStats>>,
}

mirror! {
    /// One compiled executable (a stage, or stages the driver merged) and its statistics.
    ExecutableStats from motu_gpu::PipelineExecutable {
        name: String,
        description: String,
        stages: Vec<&'static str>,
        subgroup_size: u32,
        statistics: Vec<StatisticStats>,
        /// The driver's internal representations (often none): IR or disassembly text.
        internal_representations: Vec<RepresentationStats>,
    }
}

/// One internal representation: its text (`null` for binary data) and size.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RepresentationStats {
    pub name: String,
    pub description: String,
    pub size_bytes: u64,
    pub text: Option<String>,
}

/// One statistic as the driver named it; `value` is a number (or a bool) of `format`
/// (`bool`, `i64`, `u64`, `f64`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StatisticStats {
    pub name: String,
    pub description: String,
    pub format: &'static str,
    pub value: serde_json::Value,
}

impl From<&motu_gpu::CapturedPipeline> for PipelineStats {
    fn from(p: &motu_gpu::CapturedPipeline) -> Self {
        Self {
            label: p.label.clone(),
            kind: p.kind,
            raygen_stack_bytes: p.raygen_stack_bytes,
            executables: p.stats.as_ref().map(|s| Mirror::mirror(&s.executables)),
        }
    }
}

/// Its size and its text (`null` for binary data), not its bytes.
impl Mirror<motu_gpu::InternalRepresentation> for RepresentationStats {
    fn mirror(r: &motu_gpu::InternalRepresentation) -> Self {
        Self {
            name: r.name.clone(),
            description: r.description.clone(),
            size_bytes: r.data.len() as u64,
            text: r.text(),
        }
    }
}

/// The value as a JSON number (or bool) with its format's name.
impl Mirror<motu_gpu::PipelineStatistic> for StatisticStats {
    fn mirror(s: &motu_gpu::PipelineStatistic) -> Self {
        use motu_gpu::StatisticValue as V;
        let value = match s.value {
            V::Bool(b) => serde_json::Value::from(b),
            V::I64(v) => serde_json::Value::from(v),
            V::U64(v) => serde_json::Value::from(v),
            V::F64(v) => serde_json::Value::from(v),
        };
        Self {
            name: s.name.clone(),
            description: s.description.clone(),
            format: s.value.format(),
            value,
        }
    }
}

/// The pipelines `ctx` made, when `--pipeline-stats` asked for them (`None` otherwise).
pub(crate) fn captured(ctx: &motu_gpu::Context) -> Option<Vec<PipelineStats>> {
    ctx.pipeline_stats_requested()
        .then(|| ctx.captured_pipelines().iter().map(Into::into).collect())
}
