#!/usr/bin/env bash
# A/B timing on a GPU machine (pipeline backend): each configuration line of $CONFIGS renders
# --frames 31 at SIZE with each binary of $BINS, after a warm-up render; every render is a fresh
# process, and rounds alternate configurations and binaries (BINS order within a configuration),
# so slow drifts of the machine hit every variant alike. `ms_per_frame` is the median of the
# frames after the first.
#
#   BINS="base=.dev/motu-base new=.dev/motu" CONFIGS="$(cat lines)" bash tools/speed-ab.sh
#
# CONFIGS: one configuration per line, `NAME SCENE IMPORT_FLAGS|- RENDER_FLAGS...`, where SCENE
# is a `motu gen` kind with its flags joined by commas (`island,--scale,0.15`), IMPORT_FLAGS
# the import's flags joined by commas (or `-`), and RENDER_FLAGS may start with VAR=value
# words (set for that render only; `MOTU_LOG=debug` before IMPORT_FLAGS's commas sets
# it for the import: `MOTU_LOG=debug,--max-instances,2000000`; `bin=NAME` imports with
# that binary of BINS instead of the first). `@dolly` in RENDER_FLAGS
# becomes `--camera-path` of a 31-camera dolly to 45% of the way to the scene's LookAt target;
# `only=NAME` renders the configuration with that binary alone.
# Scenes and packages are made once (by the first binary) in SPEED_WORK and reused by later
# calls. Columns of ab.tsv: binary, configuration, round, ms/frame, traces/ray, LOD passes,
# mean LOD pass ms, PI-list overflows, TLASes with a box list, md5 of the image (first 10).
# Environment: SIZE (1920x1080), ROUNDS (2), OUT (./speed-out: ab.tsv, summary.txt),
# SPEED_WORK (target/motu-speed). Loader and driver: tools/device-env.sh.
set -uo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
SIZE=${SIZE:-1920x1080}
ROUNDS=${ROUNDS:-2}
OUT=${OUT:-$ROOT/speed-out}
WORK=${SPEED_WORK:-$ROOT/target/motu-speed}
NAME=speed-ab
. "$ROOT/tools/device-env.sh"
[ -n "${BINS:-}" ] || BINS="motu=$MOTU"
[ -n "${CONFIGS:-}" ] || die "CONFIGS is empty (see the header)"
FIRST_BIN=${BINS%% *}
FIRST_BIN=${FIRST_BIN#*=}

# Generates scene `$1` (commas for spaces) once; prints its folder.
scene() {
    local dir="$WORK/gen-${1//[^A-Za-z0-9.]/_}"
    if [ ! -f "$dir/scene.pbrt" ]; then
        step "gen ${1//,/ }" >&2
        "$FIRST_BIN" gen ${1//,/ } -o "$dir" >/dev/null || die "gen $1 failed"
    fi
    echo "$dir"
}
# Imports scene folder `$1` with flags `$2` (commas for spaces, leading VAR=value words set
# for the import) once; prints the package.
package() {
    local key="${2//[^A-Za-z0-9.=]/_}"
    local pkg="$1-$key.motu"
    if [ ! -f "$pkg" ]; then
        local words=() envs=() bin=$FIRST_BIN
        [ "$2" != "-" ] && for w in ${2//,/ }; do
            if [[ $w == bin=* ]]; then
                for b in $BINS; do [ "${b%%=*}" = "${w#bin=}" ] && bin=${b#*=}; done
            elif [[ $w == *=* && $w != -* ]]; then envs+=("$w")
            else words+=("$w"); fi
        done
        step "import $(basename "$1") ${envs[*]} ${words[*]} ($bin)" >&2
        env "${envs[@]}" "$bin" import "$1/scene.pbrt" -o "$pkg" "${words[@]}" >/dev/null ||
            die "import $1 $2 failed"
    fi
    echo "$pkg"
}
# A 31-camera dolly from the scene's LookAt eye to 45% of the way to its target.
dolly() {
    [ -f "$1/dolly.json" ] || python3 - "$1/scene.pbrt" "$W" "$H" >"$1/dolly.json" <<'PY'
import json, sys
s = open(sys.argv[1]).read()
t = s.split()
i = t.index("LookAt")
n = [float(v) for v in t[i + 1:i + 10]]
eye, at, up = n[0:3], n[3:6], n[6:9]
fov = float(s.split('"float fov"')[1].split("[")[1].split("]")[0]) if '"float fov"' in s else 50.0
fwd = [at[k] - eye[k] for k in range(3)]
frames = [{"eye": [eye[k] + 0.45 * f / 30 * fwd[k] for k in range(3)], "forward": fwd,
           "up": up, "fov_deg": fov} for f in range(31)]
print(json.dumps({"format": "motu-camera-path", "version": 1, "width": int(sys.argv[2]),
                  "height": int(sys.argv[3]), "frames": frames}))
PY
    echo "$1/dolly.json"
}

# Resolve every configuration once: name, package, env words, render flags.
declare -a NAMES PKGS ENVS FLAGS ONLY
while read -r name sc imp rest; do
    [ -n "${name:-}" ] || continue
    dir=$(scene "$sc") || exit 1
    pkg=$(package "$dir" "$imp") || exit 1
    envs="" flags="" only=""
    for w in $rest; do
        if [[ $w == only=* ]]; then only=${w#only=}
        elif [[ $w == *=* && $w != -* ]]; then envs+=" $w"
        elif [ "$w" = "@dolly" ]; then flags+=" --camera-path=$(dolly "$dir")"
        else flags+=" $w"; fi
    done
    NAMES+=("$name") PKGS+=("$pkg") ENVS+=("$envs") FLAGS+=("$flags") ONLY+=("$only")
done <<<"$CONFIGS"

step "warm-up render"
"$FIRST_BIN" render "${PKGS[0]}" -o "$WORK/warm.png" --backend pipeline --width "$W" \
    --height "$H" --frames 5 >/dev/null 2>&1
for r in $(seq 1 "$ROUNDS"); do
    step "round $r"
    for i in "${!NAMES[@]}"; do
        for b in $BINS; do
            bn=${b%%=*} bp=${b#*=}
            [ -n "${ONLY[$i]}" ] && [ "${ONLY[$i]}" != "$bn" ] && continue
            stats="$WORK/${bn}-${NAMES[$i]}-$r.json"
            # shellcheck disable=SC2086
            env ${ENVS[$i]} "$bp" render "${PKGS[$i]}" -o "$WORK/${bn}-${NAMES[$i]}.png" \
                --backend pipeline --width "$W" --height "$H" --frames 31 --stats "$stats" \
                ${FLAGS[$i]} >"$WORK/${bn}-${NAMES[$i]}-$r.log" 2>&1 ||
                { tail -3 "$WORK/${bn}-${NAMES[$i]}-$r.log"; die "render $bn ${NAMES[$i]} failed"; }
            python3 - "$stats" "$bn" "${NAMES[$i]}" "$r" "$WORK/${bn}-${NAMES[$i]}.png" \
                >>"$OUT/ab.tsv" <<'PY'
import hashlib, json, sys
st = json.load(open(sys.argv[1]))
res = st.get("resources", {})
png = hashlib.md5(open(sys.argv[5], "rb").read()).hexdigest()[:10]
print(f"{sys.argv[2]}\t{sys.argv[3]}\t{sys.argv[4]}\t{st['ms_per_frame']:.4f}\t"
      f"{st['traces_per_ray']:.3f}\t{st.get('lod_passes', 0)}\t{st.get('lod_pass_ms', 0):.4f}\t"
      f"{st.get('pi_list_overflows', 0)}\t{res.get('box_list_tlases', '-')}\t{png}")
PY
            tail -1 "$OUT/ab.tsv"
        done
    done
done
step "medians per binary and configuration (ms/frame over rounds)"
python3 - "$OUT/ab.tsv" <<'PY' | tee -a "$OUT/summary.txt"
import statistics, sys
rows = [l.rstrip("\n").split("\t") for l in open(sys.argv[1]) if l.strip()]
ms = {}
for b, c, r, m, *_ in rows:
    ms.setdefault((c, b), []).append(float(m))
for (c, b), v in sorted(ms.items()):
    print(f"{c:28s} {b:6s} median {statistics.median(v):8.4f}  rounds {', '.join(f'{x:.4f}' for x in v)}")
PY
step "done"
