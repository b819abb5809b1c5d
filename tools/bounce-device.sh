#!/usr/bin/env bash
# The frame-time cost of `--bounces` on a GPU machine (issue 47): the courtyard (`gen
# courtyard`, lit by a sky map and a sun through an opening) and, if present, an island
# package, rendered by the full build with --bounces 0, 1 and 2, alternated over ROUNDS after a
# warm-up, FRAMES frames each; ms_per_frame from --stats. With STREAM_BUDGET the same runs
# are repeated streamed (`--stream --vram-budget STREAM_BUDGET`, bounces carried across passes;
# `passes` of the last frame printed too). `--bounces` defaults to 1: every run names it.
#
#   PKGS="target/motu-ttfp/island-0.63.motu" bash tools/bounce-device.sh
#   STREAM_BUDGET=8GiB PKGS=... bash tools/bounce-device.sh
#
# Environment: PKGS (extra packages), SIZE (default 640x360), FRAMES (default 20), ROUNDS
# (default 2), OUT (default ./bounce-out), BOUNCE_WORK (default target/motu-bounce),
# STREAM_BUDGET (default none: full builds only).
set -uo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
SIZE=${SIZE:-640x360}
FRAMES=${FRAMES:-20}
ROUNDS=${ROUNDS:-2}
OUT=${OUT:-$ROOT/bounce-out}
WORK=${BOUNCE_WORK:-$ROOT/target/motu-bounce}
NAME=bounce-device
. "$ROOT/tools/device-env.sh"

COURT=$WORK/courtyard.motu
if [ ! -f "$COURT" ]; then
    "$MOTU" gen courtyard -o "$WORK/courtyard" --force >/dev/null || die "gen courtyard failed"
    "$MOTU" import "$WORK/courtyard/scene.pbrt" -o "$COURT" >/dev/null || die "import failed"
fi
MODES=(full)
[ -n "${STREAM_BUDGET:-}" ] && MODES+=(stream)
for pkg in "$COURT" ${PKGS:-}; do
    name=$(basename "$pkg" .motu)
    "$MOTU" render "$pkg" -o "$WORK/warm.png" --backend pipeline --width "$W" --height "$H" \
        --bounces 0 --frames 3 >/dev/null 2>&1 || die "warm-up of $pkg failed"
    for mode in "${MODES[@]}"; do
        extra=()
        [ "$mode" = stream ] && extra=(--stream --vram-budget "$STREAM_BUDGET")
        for r in $(seq 1 "$ROUNDS"); do
            for b in 0 1 2; do
                tag=$name-$mode-b$b
                "$MOTU" render "$pkg" -o "$WORK/$tag.png" --backend pipeline --width "$W" \
                    --height "$H" --frames "$FRAMES" --bounces "$b" "${extra[@]}" \
                    --stats "$OUT/$tag-$r.json" >/dev/null 2>&1 || die "$tag failed"
                python3 -c "import json,sys; s=json.load(open(sys.argv[1])); f=(s.get('stream') or {}).get('frames') or [{}]; p=f[-1].get('passes'); print(f'  {sys.argv[2]} round {sys.argv[4]} --bounces {sys.argv[3]}: {s[\"ms_per_frame\"]:.2f} ms a frame, {s[\"rays\"]} rays' + (f', {p} passes (last frame)' if p is not None else ''))" \
                    "$OUT/$tag-$r.json" "$name $mode" "$b" "$r" | tee -a "$OUT/summary.txt"
            done
        done
    done
done
step "done"
