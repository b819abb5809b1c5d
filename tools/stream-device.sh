#!/usr/bin/env bash
# The out-of-core acceptance run of issue 14 on a GPU machine: a default `gen island --scale S`
# streamed along the default 30-frame path at a fraction of its full build, with the next
# camera's probe off and on (alternated, after a warm-up render), beside the full build.
#
#   S=0.3 FRACTION=8 bash tools/stream-device.sh
#
# Environment: S (island scale, default 0.05), FRACTION (budget = report peak / FRACTION,
# default 8), PROBES (the --stream-probe values run, default "0 1"), FRAMES (default 30), SIZE (WxH, default 640x360), ROUNDS (default 1), OUT (results,
# default ./stream-out), STREAM_WORK (scenes, default target/motu-stream). Takes the release
# binary and the loader as tools/device-env.sh says; writes report.json, full.json, and per round
# probe0-N.json / probe1-N.json (the `--stats` of each run) and a summary.txt into $OUT.
set -uo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
S=${S:-0.05}
FRACTION=${FRACTION:-8}
FRAMES=${FRAMES:-30}
SIZE=${SIZE:-640x360}
ROUNDS=${ROUNDS:-1}
OUT=${OUT:-$ROOT/stream-out}
WORK=${STREAM_WORK:-$ROOT/target/motu-stream}
NAME=stream-device
. "$ROOT/tools/device-env.sh"

. "$ROOT/tools/device-scene.sh"

render() {
    "$MOTU" render "$PKG" -o "$WORK/$1.png" --backend pipeline --width "$W" --height "$H" "${@:2}"
}
step "warm-up and full build (5 frames)"
render warm --frames 2 >/dev/null 2>&1
render full --frames 5 --stats "$OUT/full.json" >/dev/null 2>&1 || die "full build failed"
summary() {
    python3 - "$1" <<'PY' | tee -a "$OUT/summary.txt"
import json, sys
st = json.load(open(sys.argv[1]))
fr = st["stream"]["frames"]
tot = lambda k: sum(f.get(k, 0) for f in fr)
print(f"  {sys.argv[1]}: mean passes after the first {st['stream']['mean_passes_after_first']}, "
      f"frame {tot('frame_ms') / len(fr):.0f} ms, build {tot('build_ms') / len(fr):.0f} ms, "
      f"trace {tot('trace_ms') / len(fr):.0f} ms, probe {tot('probe_ms') / len(fr):.0f} ms per frame; "
      f"built {tot('built_bytes') / len(fr) / 1e9:.2f} GB per frame; peak {st['vram_peak_bytes']}")
later = sorted(f.get("frame_ms", 0) for f in fr[1:])
if later:
    print(f"    median frame after the first {later[len(later) // 2]:.0f} ms; first frame "
          f"{fr[0].get('frame_ms', 0):.0f} ms, {fr[0].get('passes', 0)} passes")
PY
}
for r in $(seq 1 "$ROUNDS"); do
    for p in ${PROBES:-0 1}; do
        step "round $r: streamed path, --stream-probe $p"
        render "probe$p-$r" --stream --vram-budget "$BUDGET" --frames "$FRAMES" --stream-probe "$p" \
            --stats "$OUT/probe$p-$r.json" >"$WORK/probe$p-$r.log" 2>&1 ||
            { tail -5 "$WORK/probe$p-$r.log"; die "streamed path failed"; }
        summary "$OUT/probe$p-$r.json"
    done
done
step "done"
