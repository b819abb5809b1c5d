use super::*;
use crate::context::{Context, ContextOptions};
use crate::testutil::context_or_skip;

fn fixed<const N: usize>(text: &str) -> [std::ffi::c_char; N] {
    let mut out = [0 as std::ffi::c_char; N];
    for (o, b) in out.iter_mut().zip(text.bytes()) {
        *o = b as std::ffi::c_char;
    }
    out
}

fn raw(
    name: &str,
    format: vk::PipelineExecutableStatisticFormatKHR,
    value: vk::PipelineExecutableStatisticValueKHR,
) -> vk::PipelineExecutableStatisticKHR<'static> {
    vk::PipelineExecutableStatisticKHR {
        name: fixed(name),
        description: fixed("  what it counts "),
        format,
        value,
        ..Default::default()
    }
}

#[test]
fn statistics_convert_by_format() {
    use vk::PipelineExecutableStatisticFormatKHR as F;
    use vk::PipelineExecutableStatisticValueKHR as V;
    let cases = [
        raw("Spilled", F::BOOL32, V { b32: vk::TRUE }),
        raw("Delta", F::INT64, V { i64: -3 }),
        raw("Register Count", F::UINT64, V { u64: 168 }),
        raw("Occupancy", F::FLOAT64, V { f64: 0.25 }),
    ];
    let got: Vec<PipelineStatistic> = cases.iter().map(statistic).collect();
    let values: Vec<StatisticValue> = got.iter().map(|s| s.value).collect();
    assert_eq!(
        values,
        [
            StatisticValue::Bool(true),
            StatisticValue::I64(-3),
            StatisticValue::U64(168),
            StatisticValue::F64(0.25)
        ]
    );
    assert_eq!(got[2].name, "Register Count");
    assert_eq!(got[2].description, "what it counts");
    let formats: Vec<&str> = values.iter().map(StatisticValue::format).collect();
    assert_eq!(formats, ["bool", "i64", "u64", "f64"]);
    assert_eq!(
        statistics_line(&got),
        "Spilled=true, Delta=-3, Register Count=168, Occupancy=0.25"
    );
}

#[test]
fn stage_names_list_every_stage() {
    use vk::ShaderStageFlags as S;
    assert_eq!(
        stage_names(S::RAYGEN_KHR | S::ANY_HIT_KHR),
        ["raygen", "any_hit"]
    );
    assert_eq!(stage_names(S::COMPUTE), ["compute"]);
    assert!(stage_names(S::empty()).is_empty());
}

/// What the test device offers, printed; asking for statistics never fails the context, and
/// nothing is logged before a pipeline is made.
#[test]
fn pipeline_stats_option_opens_on_any_device() {
    let Some(probe) = context_or_skip(
        "pipeline_stats_option_opens_on_any_device",
        crate::context::Requirement::Compute,
    ) else {
        return;
    };
    let offered = probe.has_extension("VK_KHR_pipeline_executable_properties");
    eprintln!(
        "{}: VK_KHR_pipeline_executable_properties {}, pipelineExecutableInfo {}",
        probe.device_name(),
        if offered { "offered" } else { "NOT offered" },
        probe.caps().pipeline_executable_info
    );
    assert!(!probe.pipeline_stats_requested() && !probe.pipeline_stats_enabled());
    let validation = probe.validation_enabled();
    drop(probe);
    let ctx = Context::new(&ContextOptions {
        validation: if validation {
            crate::instance::ValidationRequest::Required
        } else {
            crate::instance::ValidationRequest::Off
        },
        pipeline_stats: true,
        ..Default::default()
    })
    .expect("the option never fails the context");
    assert!(ctx.pipeline_stats_requested());
    assert_eq!(
        ctx.pipeline_stats_enabled(),
        ctx.caps().pipeline_executable_info
    );
    assert!(!ctx.caps().pipeline_executable_info || offered);
    assert!(ctx.captured_pipelines().is_empty());
    crate::testutil::assert_no_validation_errors(&ctx);
}

#[test]
fn representations_keep_the_written_bytes_and_drop_a_text_terminator() {
    let raw =
        |is_text: vk::Bool32, data_size: usize| vk::PipelineExecutableInternalRepresentationKHR {
            name: fixed("SASS"),
            description: fixed("disassembly"),
            is_text,
            data_size,
            ..Default::default()
        };
    let text = representation(&raw(vk::TRUE, 5), b"NOP;\0\0\0".to_vec());
    assert_eq!((text.name.as_str(), text.is_text), ("SASS", true));
    assert_eq!(text.text().as_deref(), Some("NOP;"));
    let binary = representation(&raw(vk::FALSE, 3), vec![1, 0, 0, 9]);
    assert_eq!(binary.data, [1, 0, 0]);
    assert_eq!(binary.text(), None);
}
