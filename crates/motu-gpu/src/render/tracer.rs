//! The trace pipeline of a backend: the ray-tracing pipeline or the ray-query compute shader,
//! specialised for the stack size, the trace cap and the payload's candidate slots.

use motu_vk::{
    CommandRecorder, ComputePipeline, ComputePipelineDesc, Context, GpuHeap, RtPipeline, RtShaders,
    PUSH_CONSTANT_BYTES,
};

use super::{Backend, RenderOptions};
use crate::error::{GpuError, Result};
use crate::shaders;

/// The largest traversal stack: entries are 64 bytes of private memory per ray, and beyond a
/// few hundred shader compilers spill, stall or fail (2^16 hangs lavapipe's compiler).
pub const MAX_STACK_SIZE: u32 = 256;

pub(crate) enum Tracer {
    Pipeline(Box<RtPipeline>),
    Query(ComputePipeline),
}

impl Tracer {
    /// The pipeline of `opts.backend` (its SBT, if any, from `heap`).
    /// `pi_capacity`: the payload's candidate slots ([`crate::scene::pi_capacity`]).
    /// `count_proxy`: with `streamed`, the counting mode's shaders (`stream/proxy_count.rs`).
    /// `streamed`: the trace shaders' streamed variant (`trace_stream.rgen` /
    /// `trace_stream.comp`, MOTU_STREAMED: a sample's secondary rays traced in windows, so its
    /// shadow and AO rays wait on their structures' builds together rather than one after
    /// another; H200, a quarter of the island's full build at 160×90: 5.05 → 4.38 passes a
    /// frame); full builds keep the sequential loop, which costs their rays less.
    pub(crate) fn new(
        ctx: &Context,
        heap: &mut GpuHeap,
        opts: &RenderOptions,
        pi_capacity: u32,
        streamed: bool,
        count_proxy: bool,
    ) -> Result<Tracer> {
        if !(1..=MAX_STACK_SIZE).contains(&opts.stack_size) || opts.max_traces_per_ray == 0 {
            return Err(GpuError::InvalidRequest(format!(
                "stack size {} is outside 1..={MAX_STACK_SIZE}, or the trace cap {} is 0",
                opts.stack_size, opts.max_traces_per_ray
            )));
        }
        // The label names the pipeline in validation messages and `--pipeline-stats`.
        let label = if streamed {
            "trace streamed"
        } else {
            "trace full"
        };
        let spec = [
            (0, opts.stack_size),
            (1, opts.max_traces_per_ray),
            (2, pi_capacity.clamp(1, crate::scene::MAX_PI_CAPACITY)),
            // COUNT_PROXY of common.glsl: streamed shaders only (`stream/proxy_count.rs`).
            (3, u32::from(streamed && count_proxy)),
        ];
        Ok(match opts.backend {
            Backend::Pipeline => {
                // The streamed variants of the raygen and the PI any-hit
                // (`pipeline/trace_stream.rgen`, `pipeline/pi_stream.rahit`).
                let shaders = RtShaders {
                    raygen: if streamed {
                        shaders::PIPELINE_TRACE_STREAM_RGEN
                    } else {
                        shaders::PIPELINE_TRACE_RGEN
                    },
                    miss: shaders::PIPELINE_MISS_RMISS,
                    triangle_closest_hit: shaders::PIPELINE_TRIANGLE_RCHIT,
                    triangle_any_hit: shaders::PIPELINE_TRIANGLE_RAHIT,
                    pi_intersection: shaders::PIPELINE_PI_RINT,
                    pi_any_hit: if streamed {
                        shaders::PIPELINE_PI_STREAM_RAHIT
                    } else {
                        shaders::PIPELINE_PI_RAHIT
                    },
                    // Proxy boxes exist only in streamed TLASes; the full build's pipelines
                    // give their (unused) group the PI shaders.
                    proxy_intersection: if streamed {
                        shaders::PIPELINE_PROXY_STREAM_RINT
                    } else {
                        shaders::PIPELINE_PI_RINT
                    },
                    proxy_any_hit: if streamed {
                        shaders::PIPELINE_PROXY_STREAM_RAHIT
                    } else {
                        shaders::PIPELINE_PI_RAHIT
                    },
                };
                Tracer::Pipeline(Box::new(RtPipeline::new(
                    ctx, heap, label, &spec, &shaders,
                )?))
            }
            Backend::Query => {
                if !ctx.caps().ray_query {
                    return Err(GpuError::MissingFeature {
                        what: "ray queries (VK_KHR_ray_query) for backend `query`; use `pipeline`"
                            .into(),
                        details: ctx.device_name().to_string(),
                    });
                }
                Tracer::Query(ComputePipeline::new(
                    ctx,
                    &ComputePipelineDesc {
                        label,
                        spirv: if streamed {
                            shaders::QUERY_TRACE_STREAM_COMP
                        } else {
                            shaders::QUERY_TRACE_COMP
                        },
                        storage_buffer_count: 0,
                        push_constant_size_bytes: PUSH_CONSTANT_BYTES,
                        specialization: &spec,
                    },
                )?)
            }
        })
    }

    pub(crate) fn release(self, heap: &mut GpuHeap) {
        if let Tracer::Pipeline(p) = self {
            p.release(heap);
        }
    }

    /// Records one trace of `dims` invocations (pipeline: a launch of `dims`; query: 8 × 8
    /// groups covering `dims`, or `groups` verbatim when given).
    pub(crate) fn record<'a>(
        &'a self,
        rec: &mut CommandRecorder<'a>,
        push_bytes: &[u8],
        dims: [u32; 2],
        groups: Option<[u32; 2]>,
    ) -> Result<()> {
        match self {
            // The pipeline, its SBT, and every buffer behind the pushed addresses live until
            // the fenced submission returns.
            Tracer::Pipeline(p) => Ok(rec.trace_rays(p, push_bytes, dims)?),
            Tracer::Query(q) => {
                let g = groups.unwrap_or([dims[0].div_ceil(8), dims[1].div_ceil(8)]);
                Ok(rec.dispatch(q, None, push_bytes, [g[0], g[1], 1])?)
            }
        }
    }
}
