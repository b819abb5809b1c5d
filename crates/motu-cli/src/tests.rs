use super::*;

#[test]
fn regression_control_bytes_from_inputs_are_escaped() {
    let e = anyhow::anyhow!("ctl.pbrt:2:1: unknown directive (at `\x1b[31mBad\x07\0`)");
    let shown = error_paragraph(&e);
    assert!(!shown.chars().any(|c| c.is_control()), "{shown:?}");
    assert!(shown.contains("\\u{1b}[31mBad\\u{7}\\u{0}"), "{shown}");
    assert_eq!(terminal_safe("a\tb\nc"), "a\tb\nc");
}

#[test]
fn regression_error_text_is_not_repeated() {
    let io = std::io::Error::other("No such device (os error 19)");
    let inner = anyhow::Error::new(io).context("scene.pbrt: No such device (os error 19)");
    let e = inner.context("importing scene.pbrt");
    assert_eq!(
        error_paragraph(&e),
        "importing scene.pbrt: scene.pbrt: No such device (os error 19)"
    );
}

/// `motu render pkg -o x.png` with `flags`, parsed.
fn render_args(flags: &[&str]) -> cli::RenderArgs {
    let args = ["motu", "render", "pkg", "-o", "x.png"].iter().chain(flags);
    let cli::Command::Render(a) = cli::Cli::try_parse_from(args).unwrap().command else {
        panic!("not render")
    };
    a
}

/// The viewer and flights light scenes with `motu_render::ShadingOptions::default()`: it
/// must stay `motu render`'s defaults, and the bounds flags map one to one.
#[test]
fn render_library_defaults_are_the_render_flags_defaults() {
    let a = render_args(&[]);
    let o = motu_render::ShadingOptions::default();
    assert_eq!(
        (
            o.ao_samples,
            o.spp,
            o.auto_exposure,
            o.bounces,
            o.ao_reach_of_diagonal
        ),
        (
            a.ao_samples,
            a.spp,
            a.exposure == cli::ExposureArg::Auto,
            a.bounces,
            a.ao_reach
        )
    );
    let b = cmd::render::stream_bounds(&a.stream_bounds);
    assert!(!b.given());
    // The viewer's lighting flags default as render's, and take the same values.
    let view = |flags: &[&str]| {
        let args = ["motu", "view", "pkg"].iter().chain(flags);
        match cli::Cli::try_parse_from(args).map(|c| c.command) {
            Ok(cli::Command::View(v)) => Ok((v.ao_reach, v.bounces)),
            Ok(_) => panic!("not view"),
            Err(e) => Err(e.to_string()),
        }
    };
    assert_eq!(view(&[]), Ok((a.ao_reach, a.bounces)));
    assert_eq!(
        view(&["--ao-reach", "0.05", "--bounces", "0"]),
        Ok((0.05, 0))
    );
    assert!(view(&["--ao-reach", "0"]).is_err());
    // A flight's: only with --camera-path.
    let bench = |flags: &[&str]| {
        let args = ["motu", "bench"].iter().chain(flags);
        cli::Cli::try_parse_from(args)
            .map(|_| ())
            .map_err(|e| e.to_string())
    };
    let fly = [
        "--camera-path",
        "p.json",
        "--package",
        "pkg",
        "--ao-reach",
        "0.05",
    ];
    assert_eq!(bench(&fly), Ok(()));
    assert!(bench(&["--ao-reach", "0.05"]).is_err());
    let a = render_args(&[
        "--stream-fallback",
        "coarse",
        "--stream-build-budget",
        "1MiB",
        "--stream-build-ms",
        "2.5",
    ]);
    let o = cmd::render::stream_bounds(&a.stream_bounds).options();
    assert!(cmd::render::stream_bounds(&a.stream_bounds).given());
    assert_eq!(o.fallback, motu_gpu::StreamFallback::Coarse);
    assert_eq!(o.frame_build_bytes, 1 << 20);
    assert_eq!(o.frame_build_ms, 2.5);
    assert_eq!(o.frame_ms, 0.0);
    // The whole-frame clock: a positive number of milliseconds.
    let a = render_args(&["--stream-frame-ms", "50"]);
    let b = cmd::render::stream_bounds(&a.stream_bounds);
    assert!(b.given());
    assert_eq!(b.options().frame_ms, 50.0);
    for bad in ["0", "-1", "nan"] {
        let args = [
            "motu",
            "render",
            "pkg",
            "-o",
            "x.png",
            "--stream-frame-ms",
            bad,
        ];
        assert!(cli::Cli::try_parse_from(args).is_err(), "{bad}");
    }
    assert_eq!(o.max_passes, motu_gpu::StreamOptions::default().max_passes);
    // The probe: every pixel unless --stream-probe says otherwise (0: off).
    let d = motu_gpu::StreamOptions::default();
    assert_eq!((o.probe_stride, d.probe_stride), (1, 1));
    let b = cmd::render::stream_bounds(&render_args(&["--stream-probe", "0"]).stream_bounds);
    assert!(b.given(), "--stream-probe needs --stream");
    assert_eq!(b.options().probe_stride, 0);
    // Probe rounds: one by default, any count from 1.
    assert_eq!(d.probe_rounds, 1);
    let b = cmd::render::stream_bounds(&render_args(&["--stream-probe-rounds", "2"]).stream_bounds);
    assert!(b.given(), "--stream-probe-rounds needs --stream");
    assert_eq!(b.options().probe_rounds, 2);
    // On the clock a cheaper probe (a 4th of each axis, one round, no verifying round); each
    // setting given wins.
    assert_eq!(o.clocked_probe, Some(motu_gpu::CLOCKED_PROBE));
    let given = ["--stream-probe", "2", "--stream-probe-rounds", "3"];
    let b = cmd::render::stream_bounds(&render_args(&given).stream_bounds);
    let want = motu_gpu::ProbeSettings {
        stride: 2,
        rounds: 3,
        ..motu_gpu::CLOCKED_PROBE
    };
    assert_eq!(b.options().clocked_probe, Some(want));
    // A flag's value clap refuses: the error names the flag.
    let refused = |flag: &str, value: &str| {
        let args = ["motu", "render", "pkg", "-o", "x.png", flag, value];
        let e = cli::Cli::try_parse_from(args).unwrap_err().to_string();
        assert!(e.contains(flag), "{e}");
    };
    refused("--stream-probe-rounds", "0");
    // Verifying rounds: none by default, any count turns them on.
    assert_eq!(d.probe_verify_rounds, 0);
    let b = cmd::render::stream_bounds(&render_args(&["--stream-probe-verify", "2"]).stream_bounds);
    assert!(b.given(), "--stream-probe-verify needs --stream");
    assert_eq!(b.options().probe_verify_rounds, 2);
    // Later rounds: open-pixel rounds first by default; verify merges them into the verifying
    // rounds; any other value is refused by name.
    assert_eq!(d.probe_later, motu_gpu::ProbeLater::Open);
    assert_eq!(o.probe_later, motu_gpu::ProbeLater::Open);
    for (value, want) in [
        ("open", motu_gpu::ProbeLater::Open),
        ("verify", motu_gpu::ProbeLater::Verify),
    ] {
        let b = cmd::render::stream_bounds(
            &render_args(&["--stream-probe-later", value]).stream_bounds,
        );
        assert!(b.given(), "--stream-probe-later needs --stream");
        assert_eq!(b.options().probe_later, want);
    }
    refused("--stream-probe-later", "all");
    // Pass marks: auto by default (also without a probe: it then marks nothing), any row
    // stride; an explicit stride or auto contradicting --stream-probe 0 is refused by name.
    assert_eq!(d.pass_marks, motu_gpu::PassMarks::Auto);
    assert_eq!(o.pass_marks, motu_gpu::PassMarks::Auto);
    let b = cmd::render::stream_bounds(&render_args(&["--stream-probe", "0"]).stream_bounds);
    assert_eq!(b.conflict(), None, "the default pass marks with no probe");
    // Draining blocks: off by default, a bound that needs --stream.
    assert!(!d.defrag && !o.defrag);
    let b = cmd::render::stream_bounds(&render_args(&["--stream-defrag"]).stream_bounds);
    assert!(b.given(), "--stream-defrag needs --stream");
    assert!(b.options().defrag);
    // Mesh memory: auto by default (host on a discrete GPU); device and host name it.
    assert_eq!(d.mesh_memory, motu_gpu::MeshMemory::Auto);
    assert_eq!(o.mesh_memory, motu_gpu::MeshMemory::Auto);
    for (flag, want) in [
        ("device", motu_gpu::MeshMemory::Device),
        ("host", motu_gpu::MeshMemory::Host),
    ] {
        let b =
            cmd::render::stream_bounds(&render_args(&["--stream-mesh-memory", flag]).stream_bounds);
        assert!(b.given(), "--stream-mesh-memory needs --stream");
        assert_eq!(b.options().mesh_memory, want);
    }
    for (flag, want) in [
        ("2", motu_gpu::PassMarks::Rows(2)),
        ("0", motu_gpu::PassMarks::Off),
        ("auto", motu_gpu::PassMarks::Auto),
    ] {
        let b = cmd::render::stream_bounds(
            &render_args(&["--stream-probe-pass-rows", flag]).stream_bounds,
        );
        assert!(b.given(), "--stream-probe-pass-rows needs --stream");
        assert_eq!(b.options().pass_marks, want);
        assert_eq!(b.conflict(), None);
    }
    let b = cmd::render::stream_bounds(
        &render_args(&["--stream-probe-pass-rows", "2", "--stream-probe", "0"]).stream_bounds,
    );
    let e = b.conflict().expect("pass rows without a probe");
    assert!(
        e.contains("--stream-probe-pass-rows 2") && e.contains("--stream-probe 0"),
        "{e}"
    );
    let b = cmd::render::stream_bounds(
        &render_args(&["--stream-probe-pass-rows", "auto", "--stream-probe", "0"]).stream_bounds,
    );
    let e = b.conflict().expect("auto pass marks without a probe");
    assert!(e.contains("--stream-probe-pass-rows auto"), "{e}");
    refused("--stream-probe-pass-rows", "two");
    // The load-time split: default (None: a million), any count from 2, 0 for none; 1 is
    // refused with the reason.
    assert_eq!(b.split_instances, None);
    for (flag, want) in [("0", 0), ("2", 2), ("4000", 4000)] {
        let a = render_args(&["--stream-split-instances", flag]);
        let b = cmd::render::stream_bounds(&a.stream_bounds);
        assert!(b.given(), "--stream-split-instances needs --stream");
        assert_eq!(b.split_instances, Some(want));
    }
    for bad in ["1", "many", "5000000000"] {
        refused("--stream-split-instances", bad);
    }
}

/// `motu import pkg -o x.motu` with `flags`, parsed.
fn import_args(flags: &[&str]) -> Result<cli::ImportArgs, clap::Error> {
    let args = ["motu", "import", "scene.pbrt", "-o", "x.motu"]
        .iter()
        .chain(flags);
    match cli::Cli::try_parse_from(args)?.command {
        cli::Command::Import(a) => Ok(a),
        _ => panic!("not import"),
    }
}

/// The import's split cap takes render's counts: default a million, any count from 2, 0 for
/// none; 1 and non-counts refused with the reason.
#[test]
fn import_split_cap_parses_as_renders() {
    let a = import_args(&[]).expect("defaults");
    assert_eq!(
        a.stream_split_instances,
        motu_compile::STREAM_SPLIT_INSTANCES
    );
    for (flag, want) in [("0", 0), ("2", 2), ("64", 64)] {
        let a = import_args(&["--stream-split-instances", flag]).expect(flag);
        assert_eq!(a.stream_split_instances, want);
    }
    for bad in ["1", "many", "5000000000"] {
        let e = import_args(&["--stream-split-instances", bad])
            .expect_err(bad)
            .to_string();
        assert!(e.contains("--stream-split-instances"), "{e}");
    }
    let e = import_args(&["--stream-split-instances", "1"])
        .expect_err("1")
        .to_string();
    assert!(e.contains("at least 2 instances"), "{e}");
}

/// `--pipeline-stats` is off by default and reaches the device request.
#[test]
fn pipeline_stats_flag_parses_into_the_device_request() {
    let off = render_args(&[]);
    assert!(!off.pipeline_stats);
    assert!(!cmd::render::device_request(&off).pipeline_stats);
    let on = render_args(&["--pipeline-stats", "--stats", "s.json"]);
    assert!(on.pipeline_stats);
    assert!(cmd::render::device_request(&on).pipeline_stats);
    assert!(cli::Cli::try_parse_from([
        "motu",
        "render",
        "pkg",
        "-o",
        "x.png",
        "--pipeline-stats=1"
    ])
    .is_err());
}

#[test]
fn stream_rates_default_to_measured_and_fix_what_they_name() {
    let rates = |flags: &[&str]| cmd::render::stream_bounds(&render_args(flags).stream_bounds);
    // Default: measured (no fixed rates), not a streaming flag given.
    let b = rates(&[]);
    assert_eq!((b.fixed_rates, b.options().fixed_rates), (None, None));
    assert_eq!(rates(&["--stream-rates", "measured"]), b);
    // Fixed: what is named, the rest unknown; needs --stream.
    let b = rates(&["--stream-rates", "build=0.5,restore=4+0.1"]);
    assert!(b.given());
    let r = b.options().fixed_rates.expect("fixed");
    assert_eq!(
        r.build.map(|r| (r.per_blas_ms, r.gb_per_s)),
        Some((0.0, 0.5))
    );
    assert_eq!(
        r.restore.map(|r| (r.per_blas_ms, r.gb_per_s)),
        Some((0.1, 4.0))
    );
    assert_eq!((r.disk_read, r.store), (None, None));
    let b = rates(&["--stream-rates", "unmeasured"]);
    assert_eq!(b.fixed_rates, Some(motu_gpu::DeviceRates::default()));
    for bad in ["", "fast", "build=0", "build=1,build=2", "read=1"] {
        let args = [
            "motu",
            "render",
            "pkg",
            "-o",
            "x.png",
            "--stream-rates",
            bad,
        ];
        let e = cli::Cli::try_parse_from(args).map(|_| ()).unwrap_err();
        assert!(e.to_string().contains("measured, unmeasured"), "{bad}: {e}");
    }
}
