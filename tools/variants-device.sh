#!/usr/bin/env bash
# Release binaries side by side on a GPU machine (the device tool: carry .gl and .dev):
# .dev/motu (the baseline, also used to generate) and each variant .dev/NAME named in VARS, on a
# default `gen island --scale S`: all-resident streamed frames (shaded and heatmap, alternated,
# two rounds), the 1/4 and 1/8 paths, and every PNG's checksum (variants must agree). Variants
# named in Q4 (space-separated) import their own package (a variant that changes the package,
# e.g. CLUSTER_INSTANCES); the rest render the baseline's.
#
#   OUT=$OUT VARS="motu motu-qmb" bash tools/variants-device.sh
#
# Environment: S (0.3), W, H (640x360), FR (1/4 path frames, 6), ROUNDS (all-resident rounds, 2),
# EIGHTH (0: skip the 1/8 path), VARS, Q4, OUT (required). Binaries may come xz-compressed in
# .devx/NAME.xz (the carry limit): they are unpacked into .dev first.
# Writes summary.txt and stats.tgz (every run's --stats) into $OUT.
set -uo pipefail
ROOT=$PWD
if ! ldconfig -p | grep -q 'libvulkan\.so\.1'; then for f in .gl/*.deb; do dpkg -x $f /; done; ldconfig; fi
if [ -f /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json ]; then
  export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
  export __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
fi
for f in .devx/*.xz; do [ -f "$f" ] || continue; mkdir -p .dev; n=$(basename $f .xz); xz -dc $f > .dev/$n && chmod +x .dev/$n; done
S=${S:-0.3}; W=${W:-640}; H=${H:-360}; FR=${FR:-6}
VARS=${VARS:-"motu motu-qmb motu-rint"}
WORK=/tmp/w; mkdir -p $WORK
T0=$(date +%s)
step() { echo "== [$(($(date +%s) - T0)) s] $*" | tee -a $OUT/summary.txt; }
nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null | tee -a $OUT/summary.txt
step "gen island $S"
.dev/motu gen island --scale $S -o $WORK/isl --force >/dev/null || exit 1
for v in $VARS; do
  case " motu ${Q4:-motu-q4} " in *" $v "*) ;; *) continue ;; esac
  step "import with $v"
  /usr/bin/time -f "%e s %M kB" .dev/$v import $WORK/isl/scene.pbrt -o $WORK/$v.motu >/dev/null 2>$WORK/imp-$v.err || { tail $WORK/imp-$v.err; exit 1; }
  tail -1 $WORK/imp-$v.err | tee -a $OUT/summary.txt
done
pkg() { case " ${Q4:-motu-q4} " in *" $1 "*) echo $WORK/$1.motu ;; *) echo $WORK/motu.motu ;; esac; }
PEAK=$(.dev/motu report $WORK/motu.motu --json --width $W --height $H | python3 -c "import json,sys; print(json.load(sys.stdin)['variants'][0]['cost']['peak_bytes'])")
step "peak $PEAK"
R() { local v=$1 name=$2; shift 2; .dev/$v render $(pkg $v) -o $WORK/$name.png --backend pipeline --width $W --height $H "$@" >$WORK/$name.log 2>&1 || { tail -3 $WORK/$name.log; echo "FAILED $name"; }; }
summ() { python3 - "$@" <<'PY' | tee -a $OUT/summary.txt
import json, sys
for p in sys.argv[1:]:
    st = json.load(open(p)); fr = st["stream"]["frames"]
    later = sorted(f.get("frame_ms", 0) for f in fr[1:])
    tr = [round(f.get("trace_ms", 0), 1) for f in fr]
    med = lambda k: sorted(f.get(k, 0) for f in fr[1:])[len(fr[1:]) // 2] if fr[1:] else 0
    print(f"  {p.split('/')[-1]}: passes after first {st['stream']['mean_passes_after_first']}, median frame {later[len(later)//2] if later else 0:.0f} ms "
          f"(build {med('build_ms'):.0f}, probe {med('probe_ms'):.0f}, trace {med('trace_ms'):.1f}); first {fr[0].get('frame_ms',0):.0f} ms; trace_ms {tr}; floor {st['stream'].get('floor_bytes','?')}")
PY
}
R motu warm --frames 2
R motu full --frames 4 --stats $WORK/full.json
python3 -c "import json; print('  full ms_per_frame', json.load(open('$WORK/full.json'))['ms_per_frame'])" | tee -a $OUT/summary.txt
BIG=$((PEAK * 5 / 4))
for round in $(seq 1 ${ROUNDS:-2}); do
  for v in $VARS; do
    for view in shaded heatmap; do
      step "all resident $v $view round $round"
      R $v res-$v-$view-$round --stream --stream-always --vram-budget $BIG --no-as-cache --frames 4 --view $view --stats $WORK/res-$v-$view-$round.json
      summ $WORK/res-$v-$view-$round.json
    done
  done
done
for v in $VARS; do
  step "quarter $v"
  R $v q-$v --stream --vram-budget $((PEAK / 4)) --no-as-cache --frames $FR --stats $WORK/q-$v.json
  summ $WORK/q-$v.json
done
for v in $( [ "${EIGHTH:-1}" = 1 ] && echo $VARS ); do
  step "eighth $v"
  R $v e-$v --stream --vram-budget $((PEAK / 8)) --no-as-cache --frames 4 --stats $WORK/e-$v.json
  summ $WORK/e-$v.json
done
step "PNG equality"
for f in $WORK/*.png; do echo "$(md5sum < $f | cut -c1-12) $(basename $f)"; done | sort -k2 | tee -a $OUT/summary.txt
tar czf $OUT/stats.tgz -C $WORK $(cd $WORK && ls *.json) 2>/dev/null
step done
