#!/usr/bin/env bash
# Where a streamed frame's working set comes from (issue 45 item 4): a default `gen island
# --scale S` imported once per partition bound, streamed along the default camera path at
# fractions of each package's report peak, and the default bound's package again with fewer
# ray kinds (primary only: `--view ids`; + the lights' shadow rays: `--bounces 0 --ao-samples
# 0`; + AO: `--bounces 0`; the default adds one diffuse bounce). Counts are the device's
# (passes, working_set_bytes, room_bytes, built bytes, TLAS instance records written); lavapipe
# gives the same counts as a GPU, slower.
#
#   S=0.3 FRACTIONS="8 16" BOUNDS="65536 32768 16384" bash tools/pieces-device.sh
#
# Environment: S (island scale, default 0.002), FRACTIONS (budget = report peak / F, default
# "8 16"), BOUNDS (`--max-blas-triangles` values; "auto" = the import's own choice; default
# "auto"), KINDS (1: also the ray-kind variants at the default bound, default 1), FRAMES
# (default 6), SIZE (WxH, default 64x36), OUT (default ./pieces-out), STREAM_WORK (default
# target/motu-pieces). Writes one `--stats` JSON per run and a line per run into
# $OUT/summary.txt. Takes the release binary and the loader as tools/device-env.sh says.
set -uo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
S=${S:-0.002}
FRACTIONS=${FRACTIONS:-8 16}
BOUNDS=${BOUNDS:-auto}
KINDS=${KINDS:-1}
FRAMES=${FRAMES:-6}
SIZE=${SIZE:-64x36}
OUT=${OUT:-$ROOT/pieces-out}
WORK=${STREAM_WORK:-$ROOT/target/motu-pieces}
NAME=pieces-device
. "$ROOT/tools/device-env.sh"

SCENE=$WORK/island-$S
if [ ! -f "$SCENE/scene.pbrt" ]; then
    step "gen island --scale $S"
    "$MOTU" gen island --scale "$S" -o "$SCENE" --force >/dev/null || die "gen failed"
fi
package() { # package BOUND -> path of the package imported with that bound
    local pkg=$WORK/island-$S-$1.motu
    if [ ! -f "$pkg" ]; then
        local flag=()
        [ "$1" = auto ] || flag=(--max-blas-triangles "$1")
        "$MOTU" import "$SCENE/scene.pbrt" -o "$pkg" "${flag[@]}" >/dev/null || die "import $1 failed"
    fi
    echo "$pkg"
}
run() { # run BOUND FRACTION TAG [render flags]
    local pkg peak budget
    pkg=$(package "$1")
    "$MOTU" report "$pkg" --json --width "$W" --height "$H" >"$OUT/report-$1.json" || die "report failed"
    peak=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['variants'][0]['cost']['peak_bytes'])" "$OUT/report-$1.json")
    budget=$((peak / $2))
    "$MOTU" render "$pkg" -o "$WORK/$3.png" --backend pipeline --width "$W" --height "$H" \
        --camera palmsCam --frames "$FRAMES" --stream --vram-budget "$budget" --no-as-cache \
        --stats "$OUT/$3.json" "${@:4}" >"$WORK/$3.log" 2>&1 || { tail -5 "$WORK/$3.log"; die "$3 failed"; }
    python3 - "$OUT/$3.json" "$OUT/report-$1.json" "$3" <<'PY' | tee -a "$OUT/summary.txt"
import json, sys
st, rep, tag = json.load(open(sys.argv[1])), json.load(open(sys.argv[2])), sys.argv[3]
fr = st["stream"]["frames"]
col = lambda k: [f.get(k, 0) for f in fr]
mb = lambda xs: [round(x / 1e6, 1) for x in xs]
cost = rep["variants"][0]["cost"]
print(f"{tag}: BLASes {cost['blas_count']}, TLAS instances {rep['flattened_instances']}, peak "
      f"{cost['peak_bytes']}, floor {rep['streaming']['min_resident_bytes']}; passes after the "
      f"first {st['stream']['mean_passes_after_first']:.3f} {col('passes')}; working set MB "
      f"{mb(col('working_set_bytes'))} in rooms of {mb(col('room_bytes'))}; built "
      f"{sum(col('built_bytes')[1:]) / 1e6:.1f} MB after the first frame; TLAS instance records "
      f"written {sum(col('tlas_instances_written'))}")
PY
}
for b in $BOUNDS; do
    for f in $FRACTIONS; do
        step "bound $b, 1/$f"
        run "$b" "$f" "b$b-f$f"
    done
done
if [ "$KINDS" = 1 ]; then
    b=${BOUNDS%% *}
    for f in $FRACTIONS; do
        step "ray kinds, bound $b, 1/$f"
        run "$b" "$f" "ids-f$f" --view ids
        run "$b" "$f" "shadow-f$f" --bounces 0 --ao-samples 0
        run "$b" "$f" "ao-f$f" --bounces 0
    done
fi
step "done"
