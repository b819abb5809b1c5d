#!/usr/bin/env bash
# Issue 45: the streamed first frame's mesh upload (`stream.frames[0].mesh_ms` against its
# `bytes_streamed`), A/B between two motu binaries, alternated in one run so both see the same
# machine state. Prints one line per render and the median GB/s per binary and setting.
#
#   A=/path/motu-main B=target/release/motu PKG=island-0.63.motu BUDGET=8GiB \
#       bash tools/mesh-upload-ab.sh
#
# Environment: A, B (binaries; B defaults to target/release/motu), PKG (a package), BUDGET
# (--vram-budget, default 8GiB), SIZE (default 640x360), ROUNDS (default 2), THREADS (values
# of RAYON_NUM_THREADS to try, default "" = the machine's), MESH_MEMORY (--stream-mesh-memory
# auto|host|device, default auto: host-mapped meshes on a discrete GPU, staged on lavapipe),
# COLD=1 drops the package from the page cache before every render (dd iflag=nocache),
# EXTRA (more render flags, e.g. "--no-as-cache"), OUT (default ./mesh-ab-out).
set -uo pipefail
A=${A:?set A to the baseline binary}
B=${B:-target/release/motu}
PKG=${PKG:?set PKG to a package}
BUDGET=${BUDGET:-8GiB}
SIZE=${SIZE:-640x360}
ROUNDS=${ROUNDS:-2}
THREADS=${THREADS:-}
MESH_MEMORY=${MESH_MEMORY:-auto}
OUT=${OUT:-$PWD/mesh-ab-out}
mkdir -p "$OUT"
W=${SIZE%x*}
H=${SIZE#*x}
: >"$OUT/runs.tsv"
for r in $(seq 1 "$ROUNDS"); do
    for t in ${THREADS:-default}; do
        for side in A B; do
            bin=${!side}
            name="$side-t$t-r$r"
            [ "${COLD:-0}" = 1 ] && dd if="$PKG" iflag=nocache count=0 status=none
            env $([ "$t" = default ] || echo RAYON_NUM_THREADS=$t) "$bin" render "$PKG" \
                -o "$OUT/$name.png" --backend pipeline --width "$W" --height "$H" --stream \
                --vram-budget "$BUDGET" --stream-mesh-memory "$MESH_MEMORY" \
                --stats "$OUT/$name.json" ${EXTRA:-} >"$OUT/$name.log" 2>&1 ||
                { tail -3 "$OUT/$name.log"; echo "$name failed" >&2; exit 1; }
            python3 - "$OUT/$name.json" "$side" "$t" "$r" <<'PY' | tee -a "$OUT/runs.tsv"
import json, sys
f = json.load(open(sys.argv[1]))["stream"]["frames"][0]
gb = f["bytes_streamed"] / 1e9
print(f"{sys.argv[2]}\t{sys.argv[3]}\t{sys.argv[4]}\tmesh_ms={f['mesh_ms']:.0f}\tstreamed_GB={gb:.3f}\t"
      f"GB/s={gb / max(f['mesh_ms'], 1e-9) * 1e3:.2f}\tbuild_ms={f['build_ms']:.0f}")
PY
        done
    done
done
python3 - "$OUT/runs.tsv" <<'PY'
import collections, statistics, sys
by = collections.defaultdict(list)
for line in open(sys.argv[1]):
    side, t, _, _, _, rate, _ = line.rstrip("\n").split("\t")
    by[(side, t)].append(float(rate.split("=")[1]))
for (side, t), v in sorted(by.items()):
    print(f"{side} threads={t}: median {statistics.median(v):.2f} GB/s over {len(v)} renders")
PY
