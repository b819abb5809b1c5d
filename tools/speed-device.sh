#!/usr/bin/env bash
# Issue 15's table on a GPU machine (pipeline backend): each configuration renders --frames 31 at
# SIZE (the median of the frames after the first is `ms_per_frame`), after a warm-up render,
# configurations alternated within each round, every render a fresh process.
#
#   bash tools/speed-device.sh                 # all groups
#   SPEED_GROUPS="hops lod" ROUNDS=3 bash tools/speed-device.sh
#
# SPEED_GROUPS: split (island at ISLAND_SCALE, one TLAS vs --max-instances SPLIT_CAP), lod (lod-grid,
# no LOD vs --lod 4, static camera and a 31-camera dolly to 45% of the way to its target),
# hops (forest --levels 3 --grid 4x3 --leaves 8732 and sphereflake --depth 4, `sl` vs `auto`,
# the default render and --ao-samples 0). Scenes and packages are made once in SPEED_WORK and
# reused by later calls (split the groups over 10-minute calls). Environment: SIZE (default
# 1920x1080), ROUNDS (default 2), ISLAND_SCALE (default 0.15), SPLIT_CAP (default 2000000), OUT
# (default ./speed-out: results.tsv, one line per render, and summary.txt with each round's
# ratios), SPEED_WORK (default target/motu-speed). The binary and the loader: tools/device-env.sh.
set -uo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
SIZE=${SIZE:-1920x1080}
ROUNDS=${ROUNDS:-2}
ISLAND_SCALE=${ISLAND_SCALE:-0.15}
SPLIT_CAP=${SPLIT_CAP:-2000000}
GROUP_LIST=${SPEED_GROUPS:-split lod hops}
OUT=${OUT:-$ROOT/speed-out}
WORK=${SPEED_WORK:-$ROOT/target/motu-speed}
NAME=speed-device
. "$ROOT/tools/device-env.sh"

# Generates `$1` (a gen kind with flags) into $WORK/$2 once.
scene() {
    local name=$2
    [ -f "$WORK/$name/scene.pbrt" ] && return 0
    step "gen $1 → $name"
    # shellcheck disable=SC2086
    "$MOTU" gen $1 -o "$WORK/$name" --force >/dev/null || die "gen $1 failed"
}
# Imports scene `$1` with flags `$3` into $WORK/$2.motu once.
package() {
    [ -f "$WORK/$2.motu" ] && return 0
    step "import $1 $3 → $2.motu"
    # shellcheck disable=SC2086
    "$MOTU" import "$WORK/$1/scene.pbrt" -o "$WORK/$2.motu" $3 >/dev/null || die "import $2 failed"
}
# Renders package `$2` as configuration `$1` with extra flags `$3`; appends a results line.
measure() {
    local cfg=$1 pkg=$2 extra=$3 round=$4
    local stats="$WORK/$cfg-$round.json"
    # shellcheck disable=SC2086
    "$MOTU" render "$WORK/$pkg.motu" -o "$WORK/$cfg.png" --backend pipeline --width "$W" \
        --height "$H" --frames 31 --stats "$stats" $extra >"$WORK/$cfg-$round.log" 2>&1 ||
        { tail -3 "$WORK/$cfg-$round.log"; die "render $cfg failed"; }
    python3 - "$stats" "$cfg" "$round" >>"$OUT/results.tsv" <<'PY'
import json, sys
st = json.load(open(sys.argv[1]))
print(f"{sys.argv[2]}\t{sys.argv[3]}\t{st['ms_per_frame']:.4f}\t{st['traces_per_ray']:.3f}\t"
      f"{st.get('lod_passes', 0)}\t{st.get('pi_list_overflows', 0)}")
PY
    tail -1 "$OUT/results.tsv"
}
# A camera path of 31 cameras from the scene's LookAt eye to `$2` of the way to its target.
dolly() {
    python3 - "$WORK/$1/scene.pbrt" "$2" "$W" "$H" >"$WORK/$1-dolly.json" <<'PY'
import json, sys
t = open(sys.argv[1]).read().split()
i = t.index("LookAt")
n = [float(v) for v in t[i + 1:i + 10]]
eye, at, up = n[0:3], n[3:6], n[6:9]
fov = 50.0
if '"float fov"' in open(sys.argv[1]).read():
    s = open(sys.argv[1]).read()
    fov = float(s.split('"float fov"')[1].split("[")[1].split("]")[0])
frac = float(sys.argv[2])
fwd = [at[k] - eye[k] for k in range(3)]
frames = [{"eye": [eye[k] + frac * f / 30 * fwd[k] for k in range(3)], "forward": fwd, "up": up,
           "fov_deg": fov} for f in range(31)]
print(json.dumps({"format": "motu-camera-path", "version": 1, "width": int(sys.argv[3]),
                  "height": int(sys.argv[4]), "frames": frames}))
PY
}

CONFIGS=()
for g in $GROUP_LIST; do
    case $g in
    split)
        scene "island --scale $ISLAND_SCALE" island
        package island island ""
        package island island-split "--max-instances $SPLIT_CAP"
        CONFIGS+=("island-one island" "island-split island-split")
        ;;
    lod)
        scene lod-grid lod-grid
        package lod-grid lod-grid ""
        package lod-grid lod-grid-lod4 "--lod 4"
        dolly lod-grid 0.45
        CONFIGS+=("lod-none lod-grid" "lod-4 lod-grid-lod4"
            "lod-none-moving lod-grid --camera-path=$WORK/lod-grid-dolly.json"
            "lod-4-moving lod-grid-lod4 --camera-path=$WORK/lod-grid-dolly.json")
        ;;
    hops)
        scene "forest --levels 3 --grid 4x3 --leaves 8732" forest
        scene "sphereflake --depth 4" sphereflake
        for s in forest sphereflake; do
            package $s $s-sl "--levels sl"
            package $s $s-auto "--levels auto"
            CONFIGS+=("$s-sl $s-sl" "$s-auto $s-auto"
                "$s-sl-ao0 $s-sl --ao-samples=0" "$s-auto-ao0 $s-auto --ao-samples=0")
        done
        ;;
    *) die "unknown group $g (split, lod, hops)" ;;
    esac
done
[ ${#CONFIGS[@]} -gt 0 ] || die "no group to run"

step "warm-up render"
first=(${CONFIGS[0]})
"$MOTU" render "$WORK/${first[1]}.motu" -o "$WORK/warm.png" --backend pipeline --width "$W" \
    --height "$H" --frames 5 >/dev/null 2>&1
for r in $(seq 1 "$ROUNDS"); do
    step "round $r"
    for c in "${CONFIGS[@]}"; do
        set -- $c
        measure "$1" "$2" "${*:3}" "$r"
    done
done
step "ratios per round (baseline / config: above 1 is faster than the baseline)"
python3 - "$OUT/results.tsv" <<'PY' | tee -a "$OUT/summary.txt"
import sys
rows = [l.rstrip("\n").split("\t") for l in open(sys.argv[1]) if l.strip()]
ms = {(c, r): float(m) for c, r, m, *_ in rows}
pairs = [("island-one", "island-split"), ("lod-none", "lod-4"),
         ("lod-none-moving", "lod-4-moving"), ("forest-sl", "forest-auto"),
         ("forest-sl-ao0", "forest-auto-ao0"), ("sphereflake-sl", "sphereflake-auto"),
         ("sphereflake-sl-ao0", "sphereflake-auto-ao0")]
for base, cfg in pairs:
    rounds = sorted({r for c, r in ms if c == cfg})
    rs = [f"{ms[(base, r)] / ms[(cfg, r)]:.3f}" for r in rounds if (base, r) in ms]
    if rs:
        print(f"{cfg} vs {base}: {', '.join(rs)}")
PY
step "done"
