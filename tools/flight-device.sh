#!/usr/bin/env bash
# Issue 45.6's flight on a GPU machine: a default `gen island --scale S` flown along a dolly
# toward the shot camera's target (`motu bench --camera-path … --stream`) at a fraction of its
# full build, refining (`--stream-build-ms 30 --stream-fallback coarse`), once as `render_frame`
# (passes until complete or the build budget is spent, then one more: the bench's default) and
# once as the viewer flies (`--stream-passes 1`: one pass a frame, `render_progressive`),
# alternated, each with a still tail (the last pose repeated) that says when a frame at rest is
# complete. Prints each run's per-phase medians (where a flying frame's time goes).
#
#   S=0.3 FRACTION=4 bash tools/flight-device.sh
#
# Environment: S (island scale, default 0.3), FRACTION (budget = report peak / FRACTION, default
# 4), FRAMES (path frames, default 31), STILL (still frames after them, default 10), DOLLY (the
# eye's move, a fraction of its distance to the target, default 0.3), BUILD_MS (default 30),
# MODES (default "frame progressive"; `viewer`: progressive with `--next-camera extrapolated`,
# the viewer's guess of the next camera), ROUNDS (default 1), WARMUP (untimed warm-up frames on a
# renderer then dropped, default 1), EXTRA (flags added to every run), SIZE (default 640x360),
# OUT (default ./flight-out), FLIGHT_WORK (scenes; default $STREAM_WORK or target/motu-stream,
# so a package tools/stream-device.sh made is reused). Takes the release binary and the loader
# as tools/device-env.sh says; writes report.json, dolly.json, per run MODE-N.json (the bench's
# --json) and summary.txt into $OUT.
set -uo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
S=${S:-0.3}
FRACTION=${FRACTION:-4}
FRAMES=${FRAMES:-31}
STILL=${STILL:-10}
DOLLY=${DOLLY:-0.3}
BUILD_MS=${BUILD_MS:-30}
MODES=${MODES:-frame progressive}
ROUNDS=${ROUNDS:-1}
WARMUP=${WARMUP:-1}
SIZE=${SIZE:-640x360}
OUT=${OUT:-$ROOT/flight-out}
WORK=${FLIGHT_WORK:-${STREAM_WORK:-$ROOT/target/motu-stream}}
NAME=flight-device
. "$ROOT/tools/device-env.sh"

. "$ROOT/tools/device-scene.sh"
CAM=$SCENE/cameras/shotCam.pbrt

# The path: shotCam (its pbrt LookAt and fov), then its eye DOLLY of the way to its target.
python3 - "$CAM" "$DOLLY" "$W" "$H" >"$OUT/dolly.json" <<'PY' || die "no dolly path"
import json, math, re, sys
text = open(sys.argv[1]).read()
n = [float(v) for v in text.split("LookAt", 1)[1].split()[:9]]
fov = float(re.search(r'"float fov"\s*\[\s*([-0-9.eE+]+)', text).group(1))
f = [n[3 + i] - n[i] for i in range(3)]
length = math.sqrt(sum(v * v for v in f))
pose = lambda d: {"eye": [n[i] + f[i] * d for i in range(3)], "forward": [v / length for v in f],
                  "up": n[6:9], "fov_deg": fov}
print(json.dumps({"format": "motu-camera-path", "version": 1, "width": int(sys.argv[3]),
                  "height": int(sys.argv[4]), "frames": [pose(0.0), pose(float(sys.argv[2]))]}))
PY

summary() {
    python3 - "$1" <<'PY' | tee -a "$OUT/summary.txt"
import json, sys
b = json.load(open(sys.argv[1]))
rows = b["per_frame"]
n = b["frames"]
path, still = rows[1:n], rows[n:]
med = lambda k, rs=path: sorted(r.get(k, 0) for r in rs)[len(rs) // 2] if rs else 0
print(f"  {sys.argv[1]}: progressive {b['progressive']}, next camera {b['next_camera']}, build "
      f"{b['frame_build_ms']} ms; after the first frame median {b['median_wall_ms_after_first']:.1f} ms "
      f"(p95 {b['p95_wall_ms_after_first']:.1f}; renderer's frame_ms {b['median_frame_ms_after_first']:.1f}), "
      f"{b['mean_passes_after_first']:.3f} passes, median fallback {b['median_fallback_pixels']:.0f} px, "
      f"{b['incomplete_frames']} of {n} incomplete; first frame {rows[0]['wall_ms']:.0f} ms; "
      f"at rest complete after {b['still_frames_to_complete']} of {b['still_frames']}")
keys = ["frame_ms", "trace_ms", "first_pass_trace_ms", "host_ms", "build_ms", "mesh_ms", "blas_ms",
        "tlas_ms", "tables_ms", "probe_ms", "blas_built", "tlas_rebuilt", "submits", "fence_waits",
        "tlas_submits", "tlas_fence_waits", "mark_walks", "evicted", "fallback_pixels"]
print("    moving, medians: " + " ".join(f"{k}={med(k):.1f}" if isinstance(med(k), float) else f"{k}={med(k)}" for k in keys))
if still:
    print("    at rest, medians: " + " ".join(f"{k}={med(k, still):.1f}" if isinstance(med(k, still), float) else f"{k}={med(k, still)}" for k in keys))
PY
}
flags() {
    case $1 in
    frame) ;;
    progressive) echo --stream-passes 1 ;;
    viewer) echo --stream-passes 1 --next-camera extrapolated ;;
    esac
}
for m in $MODES; do
    case $m in frame | progressive | viewer) ;; *) die "unknown mode $m (frame, progressive, viewer)" ;; esac
done
for r in $(seq 1 "$ROUNDS"); do
    for m in $MODES; do
        step "round $r: $m"
        # shellcheck disable=SC2046,SC2086
        "$MOTU" bench --camera-path "$OUT/dolly.json" --package "$PKG" --stream --vram-budget "$BUDGET" \
            --stream-build-ms "$BUILD_MS" --stream-fallback coarse --frames "$FRAMES" \
            --still-frames "$STILL" --warmup "$WARMUP" --backend pipeline --json $(flags "$m") ${EXTRA:-} \
            >"$OUT/$m-$r.json" 2>"$WORK/$m-$r.log" ||
            { tail -5 "$WORK/$m-$r.log"; die "$m flight failed"; }
        summary "$OUT/$m-$r.json"
    done
done
step "done"
