//! Streamed mesh uploads (issue 45.5/45.6): a `--zstd` package streams with each compressed
//! chunk decoded at most once (before, every mesh read decoded its whole chunk three times:
//! positions and indices, primitive map, shading attributes), with meshes on the device and
//! in host memory outside the budget (blocks made ahead, `heap/spare.rs`), and in both the
//! full build's AOV.

use motu_tests::{
    gen_island_with, gpu_available, json_u64 as u, motu_json, motu_ok, render_env,
    report_peak_and_floor, s, stream_frames,
};

#[test]
fn a_zstd_package_streams_with_one_decode_per_chunk_and_the_full_builds_aov() {
    if !gpu_available() {
        return;
    }
    let dir = tempfile::tempdir().expect("temporary directory");
    let pkg = gen_island_with(dir.path(), None, &["--zstd", "3"]);
    let info = motu_json(&["info", s(&pkg), "--json"]);
    let chunks = u(&info["chunks"]);
    let view = ["--width", "64", "--height", "36", "--camera", "palmsCam"];
    let full_aov = dir.path().join("full.aov");
    render_env(&pkg, "pipeline", &full_aov, &view, &[]);
    let (peak, floor) = report_peak_and_floor(&pkg, "64", "36");
    assert!(
        peak / 4 > floor,
        "a quarter of {peak} is above the floor {floor}"
    );
    let budget = (peak / 4).to_string();
    for (memory, env) in [
        ("device", &[][..]),
        ("host", &[("MOTU_SIMULATE_DISCRETE_MEMORY", "1")][..]),
    ] {
        let aov = dir.path().join(format!("{memory}.aov"));
        let mut args = view.to_vec();
        args.extend(["--stream", "--vram-budget", &budget]);
        args.extend(["--stream-mesh-memory", memory]);
        let st = render_env(&pkg, "pipeline", &aov, &args, env);
        let frames = stream_frames(&st);
        let total = |k: &str| frames.iter().map(|f| u(&f[k])).sum::<u64>();
        let (bytes, decodes) = (total("mesh_upload_bytes"), total("mesh_chunk_decodes"));
        eprintln!(
            "{memory}: {bytes} mesh bytes, {decodes} chunk decodes of {chunks} chunks, {} \
             blocks ({} from the spare)",
            total("mesh_blocks_created"),
            total("mesh_blocks_from_spare")
        );
        assert!(bytes > 0, "{memory}: meshes were streamed");
        assert!(
            decodes <= chunks,
            "{memory}: {decodes} decodes for {chunks} chunks: a chunk decoded more than once"
        );
        assert!(
            total("mesh_blocks_created") > 0,
            "{memory}: meshes take blocks"
        );
        motu_ok(&["compare", s(&full_aov), s(&aov), "--max-mismatch", "0"]);
    }
}
