#!/usr/bin/env bash
# Issue 45's still-frame runs on a GPU machine: a default `gen island --scale S` (default 0.63)
# rendered once by the full build and streamed at 8 and 24 GiB, each with a cold and then a warm
# on-disk structure cache, timing every process from its start to its written PNG (wall clock,
# and `stream.startup` from --stats). Runs alternate after a warm-up render, so no process pays
# the GPU's cold start.
#
#   S=0.63 bash tools/ttfp-device.sh
#
# Environment: S, BUDGETS (GiB, default "8 24"), SIZE (default 640x360), ROUNDS (default 1),
# NOCACHE (default 1: each budget also runs once with --no-as-cache, before the cold cache),
# EXTRA (flags added to every streamed render, e.g. "--stream-host-cache serialize" for an A/B;
# TAG names those runs apart), OUT (default ./ttfp-out), TTFP_WORK (scenes, default target/motu-ttfp), KEEP_PBRT=1 keeps the
# generated pbrt files (they are deleted after the import to leave disk for the package).
# Writes into $OUT: import.time, report.json, per run NAME.json (--stats) and summary.txt.
set -uo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
S=${S:-0.63}
BUDGETS=${BUDGETS:-8 24}
SIZE=${SIZE:-640x360}
ROUNDS=${ROUNDS:-1}
OUT=${OUT:-$ROOT/ttfp-out}
WORK=${TTFP_WORK:-$ROOT/target/motu-ttfp}
NAME=ttfp-device
. "$ROOT/tools/device-env.sh"

PKG=$WORK/island-$S.motu
if [ ! -f "$PKG" ]; then
    step "gen island --scale $S"
    "$MOTU" gen island --scale "$S" -o "$WORK/island-$S" --force >/dev/null || die "gen failed"
    step "import (default flags)"
    /usr/bin/time -v "$MOTU" import "$WORK/island-$S/scene.pbrt" -o "$PKG" --json \
        >"$OUT/import.json" 2>"$OUT/import.time" || die "import failed"
    [ "${KEEP_PBRT:-0}" = 1 ] || rm -rf "$WORK/island-$S"
fi
step "disk: 4 GiB written with fdatasync, then read back"
dd if=/dev/zero of="$WORK/dd.test" bs=16M count=256 conv=fdatasync 2>&1 | tail -1 | tee -a "$OUT/summary.txt"
dd if="$WORK/dd.test" of=/dev/null bs=16M 2>&1 | tail -1 | tee -a "$OUT/summary.txt"
rm -f "$WORK/dd.test"
step "report"
/usr/bin/time -v "$MOTU" report "$PKG" --json --width "$W" --height "$H" >"$OUT/report.json" \
    2>"$OUT/report.time" || die "report failed"

# One process: wall seconds from start to its PNG and to exit (after the PNG: the structure
# cache persisted, --stats, the cache's queued disk writes), its --stats kept.
timed() {
    local name=$1
    shift
    local t0 t1
    t0=$(date +%s.%N)
    "$MOTU" render "$PKG" -o "$WORK/$name.png" --backend pipeline --width "$W" --height "$H" \
        --stats "$OUT/$name.json" "$@" >"$WORK/$name.log" 2>&1 ||
        { tail -5 "$WORK/$name.log"; die "$name failed"; }
    t1=$(date +%s.%N)
    python3 - "$OUT/$name.json" "$name" "$t0" "$t1" "$WORK/$name.png" <<'PY' | tee -a "$OUT/summary.txt"
import json, os, sys
st = json.load(open(sys.argv[1]))
wall = float(sys.argv[4]) - float(sys.argv[3])
# The PNG's write (its mtime): a streamed render writes and commits the image before it persists
# the structure cache (persist_ms) and writes --stats; then the cache's queued writes finish.
to_png = os.path.getmtime(sys.argv[5]) - float(sys.argv[3])
s = st.get("stream") or {}
up = s.get("startup") or {}
fr = s.get("frames") or [{}]
f0 = fr[0]
keys = ["before_render_ms", "device_ms", "split_ms", "clusters_ms", "floor_ms", "init_ms",
        "derived_ms", "persistent_choice_ms", "proxy_boxes_ms", "skeleton_ms", "first_frame_ms", "to_first_pixel_ms", "write_ms"]
parts = " ".join(f"{k[:-3]}={up[k]:.0f}" for k in keys if isinstance(up.get(k), (int, float)))
print(f"  {sys.argv[2]}: {to_png:.1f} s to the PNG, {wall:.1f} s to exit; {parts}; passes {f0.get('passes', '-')}, "
      f"build {f0.get('build_ms', 0):.0f} ms trace {f0.get('trace_ms', 0):.0f} ms, "
      f"built {f0.get('built_bytes', 0) / 1e9:.2f} GB, rebuilt {f0.get('rebuilt_blases', '-')} "
      f"restored {f0.get('restored_blases', '-')} ({f0.get('restored_bytes', 0) / 1e9:.2f} GB)")
t = s.get("totals") or {}
ph = ["mesh_ms", "blas_ms", "tlas_ms", "evict_ms", "tables_ms", "clone_ms", "cache_store_ms", "store_serialize_ms",
      "store_copy_ms", "store_put_ms", "restore_ms", "restore_read_ms", "restore_upload_ms", "restore_gpu_ms"]
print("    frame 0: " + " ".join(f"{k[:-3]}={f0[k]:.0f}" for k in ph if isinstance(f0.get(k), (int, float))))
if t:
    print(f"    totals: host cache {t.get('host_cache_mode')}, cloned {t.get('cloned_blases')} "
          f"({t.get('cloned_bytes', 0) / 1e9:.2f} GB, {t.get('clone_ms', 0):.0f} ms), from clones "
          f"{t.get('restored_from_clone')}, persisted {t.get('persisted_blases')} "
          f"({t.get('persisted_bytes', 0) / 1e9:.2f} GB, {t.get('persist_ms', 0):.0f} ms)")
d = (s.get("cache") or {}).get("disk") or {}
if d:
    busy = d.get("write_busy_ms", 0)
    rate = d.get("written_bytes", 0) / (busy * 1e6) if busy else 0
    print(f"    disk: written {d.get('written', 0)} ({d.get('written_bytes', 0) / 1e9:.2f} GB) "
          f"busy {busy:.0f} ms ({rate:.2f} GB/s), put waited {d.get('submit_wait_ms', 0):.0f} ms, "
          f"flush waited {d.get('flush_wait_ms', 0):.0f} ms, hits {d.get('hits', 0)}")
PY
}

step "warm-up (full build, 2 frames)"
"$MOTU" render "$PKG" -o "$WORK/warm.png" --backend pipeline --width "$W" --height "$H" \
    --frames 2 >/dev/null 2>&1 || die "warm-up failed"
for r in $(seq 1 "$ROUNDS"); do
    step "round $r: full build"
    timed "full-$r"
    for b in $BUDGETS; do
        CACHE=$WORK/as-cache-$b-$r
        rm -rf "$CACHE"
        if [ "${NOCACHE:-1}" = 1 ]; then
            step "round $r: streamed at $b GiB, no structure cache"
            timed "s$b${TAG:-}-none-$r" --stream --vram-budget "${b}GiB" --no-as-cache ${EXTRA:-}
        fi
        step "round $r: streamed at $b GiB, cold cache"
        timed "s$b${TAG:-}-cold-$r" --stream --vram-budget "${b}GiB" --as-cache "$CACHE" ${EXTRA:-}
        step "round $r: streamed at $b GiB, warm cache"
        timed "s$b${TAG:-}-warm-$r" --stream --vram-budget "${b}GiB" --as-cache "$CACHE" ${EXTRA:-}
        du -sh "$CACHE" | tee -a "$OUT/summary.txt"
        rm -rf "$CACHE"
    done
done
step "done"
