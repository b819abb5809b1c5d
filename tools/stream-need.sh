#!/usr/bin/env bash
# What a camera path's frames must hold, against the room a budget leaves (issue 14 item 6):
# a default `gen island --scale S` (S empty: the generator's default) rendered along the
# default path once with room for everything and pass marks on every row (each frame's
# `probe_need_bytes` is then the next frame's one-pass need: the resident BLASes and meshes its
# rays hit or pass), then streamed at each budget fraction with default flags. A frame whose
# need is above its `room_bytes` cannot be one pass at that budget while whole BLASes are the
# unit (exactly for primary visibility, VIEW=ids; a shadow ray may also be served by another of
# its occluders), so the frames over give a lower bound on the passes after the first. A third
# line estimates the need if meshes were resident apart from structures: the need's structures
# plus the meshes of the BLASes primary rays hit (`working_set_mesh_bytes` of the same path
# rendered with `--view ids`, need-primary.json; only primary hits read shading attributes).
# Where meshes live in host memory (`--stream-mesh-memory`, the default on a discrete GPU) the
# need counts VRAM alone, structures and textures (`probe_need_mesh_bytes` 0), and the third
# line is the need itself.
#
#   S=0.3 FRACTIONS="4 3 2" bash tools/stream-need.sh      # on the H200 (tools/device-env.sh)
#   FRAMES=8 SIZE=64x36 bash tools/stream-need.sh          # lavapipe, the default island
#
# Environment: S, FRACTIONS (budget = report peak / F, default "4 3 2"), FRAMES (default 12),
# SIZE (default 640x360), CAMERA (default: the scene's own), VIEW (default shaded), BACKEND
# (default pipeline), OUT (default ./need-out), STREAM_WORK (default target/motu-stream).
# Writes report.json, need.json, need-primary.json and streamed-F.json (`--stats`) and
# summary.txt into $OUT.
set -uo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
S=${S:-}
FRACTIONS=${FRACTIONS:-4 3 2}
FRAMES=${FRAMES:-12}
SIZE=${SIZE:-640x360}
CAMERA=${CAMERA:-}
VIEW=${VIEW:-shaded}
BACKEND=${BACKEND:-pipeline}
OUT=${OUT:-$ROOT/need-out}
WORK=${STREAM_WORK:-$ROOT/target/motu-stream}
NAME=stream-need
. "$ROOT/tools/device-env.sh"

TAG=${S:-default}
PKG=$WORK/island-$TAG.motu
if [ ! -f "$PKG" ]; then
    step "gen island${S:+ --scale $S}; import (default flags)"
    "$MOTU" gen island ${S:+--scale "$S"} -o "$WORK/island-$TAG" --force >/dev/null || die "gen failed"
    "$MOTU" import "$WORK/island-$TAG/scene.pbrt" -o "$PKG" >/dev/null || die "import failed"
fi
"$MOTU" report "$PKG" --json --width "$W" --height "$H" >"$OUT/report.json" || die "report failed"
PEAK=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['variants'][0]['cost']['peak_bytes'])" "$OUT/report.json")
step "peak $PEAK B"

render() {
    local name=$1 budget=$2 view=${RENDER_VIEW:-$VIEW}
    shift 2
    "$MOTU" render "$PKG" -o "$WORK/$name.png" --backend "$BACKEND" --width "$W" --height "$H" \
        --view "$view" ${CAMERA:+--camera "$CAMERA"} --stream --vram-budget "$budget" \
        --frames "$FRAMES" --stats "$OUT/$name.json" "$@" >"$WORK/$name.log" 2>&1 ||
        { tail -5 "$WORK/$name.log"; die "$name failed"; }
}
step "need: room for everything ($((PEAK * 2)) B), pass marks on every row"
render need $((PEAK * 2)) --stream-probe-pass-rows 1
RENDER_VIEW=ids render need-primary $((PEAK * 2))
for f in $FRACTIONS; do
    step "streamed at 1/$f ($((PEAK / f)) B), default flags"
    render "streamed-$f" $((PEAK / f))
    python3 - "$OUT/need.json" "$OUT/streamed-$f.json" "$f" "$OUT/need-primary.json" <<'PY' | tee -a "$OUT/summary.txt"
import json, sys
need = json.load(open(sys.argv[1]))["stream"]["frames"]
got = json.load(open(sys.argv[2]))["stream"]["frames"]
primary = json.load(open(sys.argv[4]))["stream"]["frames"]
if any(f["evicted"] for f in need):
    sys.exit("the need run evicted: it is no measure of the need")
cells, split_cells, bound, over, split_over = [], [], 0, 0, 0
for k in range(1, len(got)):
    n, room, p = need[k - 1]["probe_need_bytes"], got[k]["room_bytes"], got[k]["passes"]
    # Meshes resident apart from structures: the need's structures plus the meshes of what
    # the frame's primary rays hit.
    split = n - need[k - 1]["probe_need_mesh_bytes"] + primary[k]["working_set_mesh_bytes"]
    over += n > room
    split_over += split > room
    bound += 2 if n > room else 1
    cells.append(f"{p}:{n / room:.2f}")
    split_cells.append(f"{split / room:.2f}")
frames = len(got) - 1
mean = sum(f["passes"] for f in got[1:]) / frames
print(f"  1/{sys.argv[3]}: passes:need/room per frame after the first  {' '.join(cells)}")
print(f"  1/{sys.argv[3]}: {over} of {frames} frames over their room; passes after the first "
      f">= {bound / frames:.3f}, measured {mean:.3f}")
print(f"  1/{sys.argv[3]}: with meshes apart from structures, need/room about  "
      f"{' '.join(split_cells)} ({split_over} of {frames} over)")
PY
done
step "done"
