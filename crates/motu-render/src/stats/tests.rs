use super::*;
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};

/// Every key path of `v` with its JSON type (`int`, `float`, `string`, …); array elements
/// share the path `name[]`.
fn key_types(v: &Value, path: &str, out: &mut BTreeSet<String>) {
    let ty = match v {
        Value::Null => "null",
        Value::Bool(_) => "bool",
        Value::Number(n) if n.is_f64() => "float",
        Value::Number(_) => "int",
        Value::String(_) => "string",
        Value::Array(a) => {
            for x in a {
                key_types(x, &format!("{path}[]"), out);
            }
            "array"
        }
        Value::Object(o) => {
            for (k, x) in o {
                let p = if path.is_empty() {
                    k.clone()
                } else {
                    format!("{path}.{k}")
                };
                key_types(x, &p, out);
            }
            "object"
        }
    };
    if !path.is_empty() {
        out.insert(format!("{path} {ty}"));
    }
}

fn json<T: Serialize>(v: &T) -> Value {
    serde_json::to_value(v).expect("the schema serialises")
}

fn alloc_report() -> motu_alloc::AllocReport {
    let class = motu_alloc::ClassStats {
        counts_against_budget: true,
        budget_bytes: 1,
        standard_block_bytes: 1,
        block_count: 1,
        dedicated_block_count: 0,
        empty_block_count: 0,
        block_bytes: 1,
        in_use_bytes: 1,
        free_bytes: 0,
        free_range_count: 0,
        largest_free_range_bytes: 0,
        fragmentation: 0.0,
        peak_block_bytes: 1,
        peak_in_use_bytes: 1,
    };
    motu_alloc::AllocReport {
        budget_bytes: 1,
        max_allocation_count: 1,
        max_allocation_size_bytes: 1,
        allocation_count: 1,
        peak_allocation_count: 1,
        live_suballocation_count: 1,
        budget_block_bytes: 1,
        budget_in_use_bytes: 1,
        peak_block_bytes: 1,
        peak_in_use_bytes: 1,
        classes: BTreeMap::from([(motu_alloc::MemoryClass::DeviceLocal, class)]),
        kinds: BTreeMap::from([(
            motu_alloc::AllocKind::BlasStorage,
            motu_alloc::KindStats::default(),
        )]),
    }
}

fn resources() -> ResourceReport {
    (&motu_gpu::ResourceReport {
        alloc: Some(alloc_report()),
        ..Default::default()
    })
        .into()
}

fn stream_frame() -> motu_gpu::FrameStreamStats {
    motu_gpu::FrameStreamStats {
        pass_log: vec![motu_gpu::PassStats::default()],
        ..Default::default()
    }
}

/// Every key a render can write: a streamed GPU render with every optional part present.
fn full_render_stats() -> RenderStats {
    let floor = motu_gpu::StreamFloor {
        largest_blas: Some(0),
        ..Default::default()
    };
    let cache = motu_ascache::CacheStats {
        disk: Some(motu_ascache::DiskStats::default()),
        ..Default::default()
    };
    let denoise = crate::denoise::DenoiseStats {
        filter: "a-trous",
        iterations: 1,
        filtered_pixels: 1,
        denoise_ms: 1.0,
    };
    RenderStats {
        frame: FrameStats::gpu(&motu_gpu::RenderStats::default()),
        truncated_rays: Some(0),
        full_build: Some(FullBuildStats {
            resources: resources(),
            lod_passes: 0,
            lod_passes_skipped: 0,
            lod_refits: 0,
            lod_settles: 0,
            lod_pass_ms: 0.0,
        }),
        path_ms_per_frame: Some(vec![1.0]),
        fallback_pixels: Some(0),
        stream: Some(StreamRunStats {
            frames: vec![(&stream_frame()).into()],
            totals: (&motu_gpu::StreamTotals::default()).into(),
            floor: (&floor).into(),
            max_passes: 1,
            startup: StreamStartup {
                write_ms: Some(1.0),
                ..Default::default()
            },
            cache: Some((&cache).into()),
            mean_passes_after_first: Some(1.0),
        }),
        stream_fit: Some(StreamFitStats {
            budget_bytes: 1,
            full_build_upper_bytes: 1,
            full_build: false,
            check_ms: 1.0,
        }),
        denoise: Some((&denoise).into()),
        lod: LodStats {
            lod_mode: "none",
            lod_mode_reason: "",
            lod_instances: 0,
            lod_traversal_selectors: 0,
        },
        blas_build: "fast-trace",
        subset: vec!["main".into()],
        package: "scene.motu".into(),
        pipeline_executables: Some(vec![pipeline_stats()]),
    }
}

/// A pipeline with one executable and one statistic (the other formats write `value` as a
/// float or a bool).
fn pipeline_stats() -> PipelineStats {
    let exe = motu_gpu::PipelineExecutable {
        name: "raygen".into(),
        description: "ray generation".into(),
        stages: vec!["raygen"],
        subgroup_size: 32,
        statistics: vec![motu_gpu::PipelineStatistic {
            name: "Registers".into(),
            description: "registers per thread".into(),
            value: motu_gpu::StatisticValue::U64(1),
        }],
        internal_representations: vec![motu_gpu::InternalRepresentation {
            name: "SASS".into(),
            description: "disassembly".into(),
            is_text: true,
            data: b"NOP".to_vec(),
        }],
    };
    (&motu_gpu::CapturedPipeline {
        label: "trace full".into(),
        kind: "ray_tracing",
        raygen_stack_bytes: Some(1),
        stats: Some(motu_gpu::PipelineExecutableStats {
            executables: vec![exe],
        }),
    })
        .into()
}

fn view_stats(detail: ViewDetail) -> ViewStats {
    ViewStats {
        frame: FrameStats::gpu(&motu_gpu::RenderStats::default()),
        wall_ms_per_frame_median: 1.0,
        wall_ms_per_frame: vec![1.0],
        window: WindowStats {
            width: 1,
            height: 1,
            presented_via: "swapchain",
            panel_frames: 1,
            panel_pixels: 1,
        },
        vram_used_bytes: 0,
        resident_structures: 0,
        total_structures: 0,
        streaming: false,
        incomplete_frames: 0,
        incomplete_pixels_per_frame: vec![0],
        lod_mode: "none",
        accumulated_samples: 1,
        denoised: false,
        stream_fit: None,
        detail: Some(detail),
        package: "scene.motu".into(),
    }
}

fn device_report() -> motu_gpu::DeviceReport {
    motu_gpu::DeviceReport {
        index: 0,
        name: "llvmpipe".into(),
        driver: String::new(),
        driver_name: String::new(),
        driver_info: String::new(),
        driver_version: String::new(),
        vendor_id: 0,
        device_id: 0,
        device_type: "cpu",
        api_version: "1.3".into(),
        usable: true,
        unusable_reason: Some(String::new()),
        acceleration_structure: true,
        ray_pipeline: true,
        ray_query: true,
        buffer_device_address: true,
        memory_budget_ext: true,
        caps: motu_gpu::Caps::default(),
        limits: motu_gpu::Limits {
            max_instance_count: 1,
            max_primitive_count: 1,
            max_geometry_count: 1,
            max_memory_allocation_count: 1,
            max_memory_allocation_size: 1,
            max_storage_buffer_range: 1,
            max_buffer_size: Some(1),
            min_acceleration_structure_scratch_offset_alignment: 1,
            max_descriptor_set_acceleration_structures: 1,
            shader_group_handle_size: 1,
            shader_group_base_alignment: 1,
            shader_group_handle_alignment: 1,
            max_shader_group_stride: 1,
            max_ray_recursion_depth: 1,
            max_ray_hit_attribute_size: 1,
            max_ray_dispatch_invocation_count: 1,
            timestamp_period_ns: 1.0,
            timestamp_valid_bits: 1,
            max_push_constants_size: 1,
            max_compute_work_group_count: [1; 3],
            max_compute_work_group_invocations: 1,
            min_storage_buffer_offset_alignment: 1,
            non_coherent_atom_size: 1,
        },
        heaps: vec![motu_gpu::HeapReport {
            index: 0,
            size_bytes: 1,
            budget_bytes: Some(1),
            usage_bytes: Some(1),
            device_local: true,
        }],
        limit_overrides: vec!["max_instance_count"],
    }
}

/// The schema's documents, each with every optional part present, by name.
fn documents() -> Vec<(&'static str, Value)> {
    let (cpu_frame, truncated) = FrameStats::cpu(&motu_trace::RenderStats::default(), 1, 0);
    let cpu = RenderStats {
        frame: cpu_frame,
        truncated_rays: Some(truncated),
        full_build: None,
        path_ms_per_frame: None,
        fallback_pixels: None,
        stream: None,
        stream_fit: None,
        denoise: None,
        pipeline_executables: None,
        ..full_render_stats()
    };
    let persistent = motu_gpu::PersistentEstimate {
        auto_min_budget_bytes: Some(0),
        ..Default::default()
    };
    vec![
        ("devices", json(&DeviceList::new(&[device_report()]))),
        ("render", json(&full_render_stats())),
        ("render_cpu", json(&cpu)),
        (
            "view",
            // A streaming budget that held the scene: the full build drew it.
            json(&ViewStats {
                stream_fit: Some(StreamFitStats {
                    budget_bytes: 2,
                    full_build_upper_bytes: 1,
                    full_build: true,
                    check_ms: 1.0,
                }),
                ..view_stats(ViewDetail::Resources(Box::new(resources())))
            }),
        ),
        (
            "view_stream",
            json(&view_stats(ViewDetail::Stream(Box::new(
                (&stream_frame()).into(),
            )))),
        ),
        (
            "report_persistent_tlas",
            json(&PersistentEstimate::from(&persistent)),
        ),
        (
            "report_render_overhead",
            json(&FullBuildOverhead::from(
                &motu_gpu::FullBuildOverhead::default(),
            )),
        ),
    ]
}

/// Every key path the schema writes, with its JSON type, is in `stats/keys.txt`, and every line
/// there is still written: a key renamed, removed or retyped fails here; a key added fails
/// until the list has it (`MOTU_UPDATE_STATS_KEYS=1 cargo test -p motu-render --lib stats`
/// rewrites it; add the key to the contract notes too).
#[test]
fn schema_keys_match_the_key_list() {
    let mut text = String::from(
        "# Every key path the --stats schema writes, with its JSON type (optional parts present).\n\
         # Keys are added, never renamed or removed (shared/CLI.md); `[]` is an array element.\n",
    );
    for (doc, v) in documents() {
        let mut keys = BTreeSet::new();
        key_types(&v, "", &mut keys);
        for k in keys {
            text.push_str(&format!("{doc}: {k}\n"));
        }
    }
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/stats/keys.txt");
    if std::env::var_os("MOTU_UPDATE_STATS_KEYS").is_some_and(|v| v == "1") {
        std::fs::write(&path, &text).expect("writing keys.txt");
    }
    let listed = std::fs::read_to_string(&path).expect("reading keys.txt");
    let want: BTreeSet<&str> = listed.lines().filter(|l| !l.starts_with('#')).collect();
    let have: BTreeSet<&str> = text.lines().filter(|l| !l.starts_with('#')).collect();
    let lost: Vec<_> = want.difference(&have).collect();
    let added: Vec<_> = have.difference(&want).collect();
    assert!(
        lost.is_empty(),
        "keys of the --stats contract gone or retyped (keys are never renamed or removed): {lost:?}"
    );
    assert!(
        added.is_empty(),
        "new --stats keys not in src/stats/keys.txt (MOTU_UPDATE_STATS_KEYS=1 adds them): {added:?}"
    );
}

/// CLI.md's `--stats` keys are top-level keys of every backend's stats, never null.
#[test]
fn contract_keys_are_written_by_every_backend() {
    let frames = documents()
        .into_iter()
        .filter(|(doc, _)| doc.starts_with("render") || doc.starts_with("view"));
    for (doc, v) in frames {
        for key in CONTRACT_KEYS {
            assert!(
                v.get(key).is_some_and(|x| x.is_number() || x.is_string()),
                "{doc}: {key} missing in {v}"
            );
        }
    }
}

/// The disk tier's warnings are keyed by `WarningReason::name`, the name its logs use.
#[test]
fn cache_warnings_are_keyed_by_reason_name() {
    let mut w = motu_ascache::WarningCounts::default();
    for (i, &r) in motu_ascache::WarningReason::ALL.iter().enumerate() {
        for _ in 0..=i {
            w.count(r);
        }
    }
    let v = json(&WarningCounts::from(&w));
    assert_eq!(v.as_object().map(|o| o.len()), Some(7), "{v}");
    for r in motu_ascache::WarningReason::ALL {
        assert_eq!(v[r.name()], w.get(r), "{r}");
    }
}

/// The allocator's classes and kinds are keyed by their names.
#[test]
fn alloc_classes_and_kinds_are_keyed_by_name() {
    let r = alloc_report();
    let v = json(&AllocReport::from(&r));
    assert_eq!(v["classes"]["device_local"]["block_count"], 1, "{v}");
    assert_eq!(v["kinds"]["blas_storage"]["bytes"], 0, "{v}");
    for kind in motu_alloc::AllocKind::ALL {
        let mut r = alloc_report();
        r.kinds = BTreeMap::from([(kind, motu_alloc::KindStats::default())]);
        let v = json(&AllocReport::from(&r));
        assert!(v["kinds"].get(kind.name()).is_some(), "{kind}: {v}");
    }
}

/// The view's name is the `--view` flag's value on both tracers.
#[test]
fn frame_views_are_named_as_the_flag() {
    for (gpu, cpu, name) in [
        (motu_gpu::View::Shaded, motu_trace::View::Shaded, "shaded"),
        (motu_gpu::View::Ids, motu_trace::View::Ids, "ids"),
        (motu_gpu::View::Lod, motu_trace::View::Lod, "lod"),
        (
            motu_gpu::View::Heatmap,
            motu_trace::View::Heatmap,
            "heatmap",
        ),
        (motu_gpu::View::Albedo, motu_trace::View::Albedo, "albedo"),
    ] {
        let g = motu_gpu::RenderStats {
            view: gpu,
            ..Default::default()
        };
        let c = motu_trace::RenderStats {
            view: cpu,
            ..Default::default()
        };
        assert_eq!(json(&FrameStats::gpu(&g))["view"], name);
        assert_eq!(json(&FrameStats::cpu(&c, 1, 0).0)["view"], name);
        assert_eq!(name.parse::<motu_trace::View>(), Ok(cpu));
    }
}
