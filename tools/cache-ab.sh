#!/usr/bin/env bash
# A/B of the structure cache: two release binaries (OLD, NEW) render PKG streamed, each with an
# empty --as-cache directory (cold) and then the same directory again (warm), runs alternated
# ROUNDS times; prints wall time, the start's phases and the store/restore phases per process.
#
#   PKG=isl05.motu OLD=motu-before NEW=target/release/motu bash tools/cache-ab.sh
#
# Environment: BUDGET (default 2GiB), SIZE (64x36), BACKEND (pipeline), ROUNDS (2), OUT (cache-ab).
set -u
PKG=${PKG:?a package}
OUT=${OUT:-cache-ab}; mkdir -p "$OUT"
BUDGET=${BUDGET:-2GiB}; SIZE=${SIZE:-64x36}; BACKEND=${BACKEND:-pipeline}
for r in $(seq 1 "${ROUNDS:-2}"); do
for b in old new; do
  if [ $b = old ]; then BIN=${OLD:?the old binary}; else BIN=${NEW:?the new binary}; fi
  rm -rf $OUT/cache-$b
  for phase in cold warm; do
    t0=$(date +%s.%N)
    "$BIN" render "$PKG" -o $OUT/$b-$phase.png --backend $BACKEND --width ${SIZE%x*} --height ${SIZE#*x} --stream --vram-budget $BUDGET --as-cache $OUT/cache-$b --stats $OUT/$b-$phase-$r.json > $OUT/$b-$phase.log 2>&1 || { echo "$b $phase failed"; tail -3 $OUT/$b-$phase.log; }
    t1=$(date +%s.%N)
    python3 - $OUT/$b-$phase-$r.json $b $phase $t0 $t1 <<'PY'
import json,sys
st=json.load(open(sys.argv[1])); s=st["stream"]; up=s["startup"]; t=s["totals"]; f0=s["frames"][0]
wall=float(sys.argv[5])-float(sys.argv[4])
ph=["cache_store_ms","store_serialize_ms","store_copy_ms","store_put_ms","restore_ms","restore_read_ms","restore_upload_ms","restore_gpu_ms"]
d=(s.get("cache") or {}).get("disk") or {}
print(f"{sys.argv[2]} {sys.argv[3]}: wall {wall:.1f} s, clusters {up.get('clusters_ms',0):.0f} ms, first frame {up.get('first_frame_ms',0):.0f} ms, proxy {up.get('proxy_boxes_ms',0):.0f} ms, blas {f0.get('blas_ms',0):.0f} ms, stored {t.get('cache_stored_bytes',0)/1e6:.0f} MB, restored {t.get('restored_bytes',0)/1e6:.0f} MB; "+" ".join(f"{k[:-3]}={t[k]:.0f}" for k in ph if k in t)+f"; disk busy {d.get('write_busy_ms','-')} wait {d.get('submit_wait_ms','-')} flush {d.get('flush_wait_ms','-')}")
PY
  done
done
done
