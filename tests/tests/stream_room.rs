//! Where the budget goes beside the room (issue 45.4): each streamed frame's `room_split`
//! splits `vram_budget_bytes − room_bytes` by what holds it, and the instance table in host
//! memory (`MOTU_STREAM_TABLES=instances`; `host` also the member table and the boxes inside
//! BLASes), counted apart from the budget on a discrete GPU (`MOTU_SIMULATE_DISCRETE_MEMORY=1`
//! here), gives its bytes to the room with the same image.

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
fn room_split_sums_to_the_budget_less_the_room_and_host_tables_grow_the_room() {
    let Some((dir, pkg)) = gpu_island(None) else {
        return;
    };
    let view = ["--width", "96", "--height", "54", "--frames", "2"];
    let (peak, floor) = report_peak_and_floor(&pkg, "96", "54");
    assert!(
        peak / 8 > floor,
        "an eighth of {peak} is above the floor {floor}"
    );
    let stream = |budget: u64, name: &str, env: &[(&str, &str)]| {
        let aov = dir.path().join(format!("{name}.aov"));
        let budget = budget.to_string();
        let mut args = view.to_vec();
        args.extend(["--stream", "--stream-always", "--vram-budget", &budget]);
        args.extend(["--no-as-cache"]);
        (render_env(&pkg, "pipeline", &aov, &args, env), aov)
    };
    // The streamer's image with room for everything: every budget gives it.
    let (_, reference) = stream(peak * 2, "everything", &[]);
    let discrete = ("MOTU_SIMULATE_DISCRETE_MEMORY", "1");
    let runs = [
        ("unified", vec![]),
        ("device", vec![discrete]),
        (
            "instances",
            vec![discrete, ("MOTU_STREAM_TABLES", "instances")],
        ),
        ("host", vec![discrete, ("MOTU_STREAM_TABLES", "host")]),
    ];
    let (mut first_frames, mut rooms) = (Vec::new(), Vec::new());
    for (name, env) in &runs {
        let (st, aov) = stream(peak / 8, name, env);
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
        rooms.push(
            frames
                .iter()
                .map(|f| u(&f["room_bytes"]))
                .collect::<Vec<_>>(),
        );
        motu_ok(&["compare", s(&reference), s(&aov), "--max-mismatch", "0"]);
    }
    let tables = |f: &serde_json::Value| u(&f["room_split"]["table_bytes"]);
    let [_, device, instances, host] = &first_frames[..] else {
        unreachable!("four runs")
    };
    let table = u(&device["room_split"]["instance_table_bytes"]);
    assert!(
        table > 0,
        "the device run's instance table is in the budget"
    );
    assert_eq!(u(&instances["room_split"]["instance_table_bytes"]), 0);
    // The tables never change while streaming: the instances run's are the device run's less
    // the instance table, byte for byte; the host run's less the member table and boxes too.
    assert_eq!(
        tables(device) - tables(instances),
        table,
        "the instance table left the budget"
    );
    assert!(
        tables(host) < tables(instances),
        "the member table and the boxes inside BLASes left the budget"
    );
    // Room after each frame, summed over the frames: what is resident (so the TLAS pieces'
    // size) follows the room, so a single frame's room moves by the tables less what the
    // extra room made resident.
    let room = |i: usize| -> u64 { rooms[i].iter().sum() };
    eprintln!(
        "room (both frames): device {}, instances {}, host {} (instance table {table}, tables \
         {} → {})",
        room(1),
        room(2),
        room(3),
        tables(device),
        tables(host)
    );
    // Measured (default island, 96x54, an eighth, lavapipe): 13,291,406 → 14,970,766 (+1.68
    // MB for an instance table of 0.97 MB) → 15,769,038 (tables 1.63 → 0.16 MB).
    assert!(
        room(2) >= room(1) + table,
        "the room grows by the instance table: {} → {} ({table} bytes a frame)",
        room(1),
        room(2)
    );
    assert!(
        room(3) >= room(1) + (tables(device) - tables(host)),
        "the room grows by the tables moved: {} → {}",
        room(1),
        room(3)
    );
}
