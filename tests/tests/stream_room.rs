//! Where the budget goes beside the room (issue 45.4): each streamed frame's `room_split`
//! splits `vram_budget_bytes − room_bytes` by what holds it, and the instance table in host
//! memory (`MOTU_STREAM_INSTANCE_TABLE=host`, counted apart from the budget on a discrete GPU:
//! `MOTU_SIMULATE_DISCRETE_MEMORY=1` here) gives its bytes to the room with the same image.

use motu_tests::{
    gpu_island, json_u64 as u, motu_ok, render_env, report_peak_and_floor, s, stream_frames,
};

/// The parts of `room_split` that sum to `vram_budget_bytes − room_bytes` (the two "of
/// which" keys, `proxy_blas_bytes` and `instance_table_bytes`, are inside them).
const PARTS: [&str; 9] = [
    "skeleton_blas_bytes",
    "tlas_bytes",
    "instance_buffer_bytes",
    "table_bytes",
    "geometry_bytes",
    "texture_bytes",
    "scratch_bytes",
    "staging_bytes",
    "other_bytes",
];

#[test]
fn room_split_sums_to_the_budget_less_the_room_and_a_host_instance_table_grows_the_room() {
    let Some((dir, pkg)) = gpu_island(None) else {
        return;
    };
    let view = ["--width", "96", "--height", "54", "--frames", "2"];
    let full_aov = dir.path().join("full.aov");
    render_env(&pkg, "pipeline", &full_aov, &view, &[]);
    let (peak, floor) = report_peak_and_floor(&pkg, "96", "54");
    let budget = (peak / 8).to_string();
    assert!(
        peak / 8 > floor,
        "an eighth of {peak} is above the floor {floor}"
    );
    let mut args = view.to_vec();
    args.extend(["--stream", "--vram-budget", &budget, "--no-as-cache"]);
    let discrete = ("MOTU_SIMULATE_DISCRETE_MEMORY", "1");
    let runs = [
        ("unified", vec![]),
        ("device", vec![discrete]),
        (
            "host",
            vec![discrete, ("MOTU_STREAM_INSTANCE_TABLE", "host")],
        ),
    ];
    let mut first_frames = Vec::new();
    for (name, env) in &runs {
        let aov = dir.path().join(format!("{name}.aov"));
        let st = render_env(&pkg, "pipeline", &aov, &args, env);
        let frames = stream_frames(&st);
        assert_eq!(frames.len(), 2, "{name}: two streamed frames");
        for f in &frames {
            let split = &f["room_split"];
            let sum: u64 = PARTS.iter().map(|k| u(&split[*k])).sum();
            let (budget, room) = (u(&f["vram_budget_bytes"]), u(&f["room_bytes"]));
            eprintln!("{name}: room {room} of {budget}; split {split}");
            assert_eq!(sum, budget - room, "{name}: the parts sum to budget − room");
            assert!(
                u(&split["tlas_bytes"]) > 0,
                "{name}: TLASes hold the budget"
            );
            assert!(
                u(&split["other_bytes"]) > 0,
                "{name}: frame buffers hold the budget"
            );
            assert!(u(&split["proxy_blas_bytes"]) <= u(&split["skeleton_blas_bytes"]));
            assert!(u(&split["instance_table_bytes"]) <= u(&split["table_bytes"]));
        }
        first_frames.push(frames[0].clone());
        motu_ok(&["compare", s(&full_aov), s(&aov), "--max-mismatch", "0"]);
    }
    let [_, device, host] = &first_frames[..] else {
        unreachable!("three runs")
    };
    let table = u(&device["room_split"]["instance_table_bytes"]);
    assert!(
        table > 0,
        "the device run's instance table is in the budget"
    );
    assert_eq!(u(&host["room_split"]["instance_table_bytes"]), 0);
    // The tables never change while streaming: the host run's are the device run's less the
    // instance table, byte for byte.
    assert_eq!(
        u(&device["room_split"]["table_bytes"]) - u(&host["room_split"]["table_bytes"]),
        table,
        "the instance table left the budget"
    );
    let (room_device, room_host) = (u(&device["room_bytes"]), u(&host["room_bytes"]));
    eprintln!("room: device {room_device}, host {room_host} (instance table {table})");
    assert!(
        room_host >= room_device + table / 2,
        "the room grows by the instance table: {room_device} → {room_host} ({table} bytes)"
    );
}
