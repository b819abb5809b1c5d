#!/usr/bin/env bash
# The GPU benchmark suite on a fresh machine that has only the NVIDIA driver (issue 10):
# installs the Vulkan loader if needed, takes a carried release binary or builds one, prints
# `motu devices --json`, generates the scenes there and runs `motu bench gpu`, copying the
# results into $OUT (default ./bench-out).
#
#   bash tools/bench-device.sh [motu bench options...]
#
# Options are passed to `motu bench gpu`, e.g. `--only forest,sphereflake` or
# `--only island --configs sl` to split the suite over several time-limited calls (scenes are
# generated once into $BENCH_WORK, default target/motu-bench, and reused by later calls).
# Environment: OUT (results), BENCH_WORK (scenes, packages, logs), BENCH_DEADLINE_S (start no step
# after this many seconds of the suite; default 1380 = 23 min), BENCH_SUITE (default gpu),
# MOTU_BENCH_COMMIT (the commit to record when there is no git checkout).
#
# Files looked for: a release binary with `motu bench` at ./motu, .dev/bench/motu, .dev/motu or
# target/release/motu; the Vulkan loader's .debs in .gl/ (see the device notes); pbrt-v3
# buddha-fractal/ in .dev/bench/scenes, .dev, shared/scenes or ../shared/scenes.
set -uo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
OUT=${OUT:-$ROOT/bench-out}
WORK=${BENCH_WORK:-$ROOT/target/motu-bench}
SUITE=${BENCH_SUITE:-gpu}
DEADLINE_S=${BENCH_DEADLINE_S:-1380}
mkdir -p "$OUT" "$WORK"
T0=$(date +%s)
step() { echo "== [$(($(date +%s) - T0)) s] $*"; }
die() { echo "bench-device: $*" >&2; exit 1; }

step "machine: $(nproc) cores, $(awk '/MemTotal/ {printf "%.0f GiB", $2/1048576}' /proc/meminfo) RAM, $(df -h "$WORK" | awk 'NR==2 {print $4}') free disk"
if command -v nvidia-smi >/dev/null; then
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader || true
fi

# --- the Vulkan loader -----------------------------------------------------------------------
if ! ldconfig -p | grep -q 'libvulkan\.so\.1'; then
    if compgen -G ".gl/*.deb" >/dev/null; then
        step "installing the Vulkan loader from .gl/*.deb"
        for f in .gl/*.deb; do dpkg -x "$f" /; done
        ldconfig
    elif command -v apt-get >/dev/null; then
        step "installing libvulkan1 with apt-get"
        apt-get install -y -q libvulkan1 >/dev/null 2>&1 || true
    fi
    ldconfig -p | grep -q 'libvulkan\.so\.1' ||
        die "no Vulkan loader (libvulkan.so.1): put the libvulkan1 .deb into .gl/ or install libvulkan1"
fi

# --- the motu binary -------------------------------------------------------------------------
MOTU=
for c in ./motu .dev/bench/motu .dev/motu target/release/motu; do
    # An older binary without `motu bench` is passed over.
    if [ -x "$c" ] && "$c" bench --help >/dev/null 2>&1; then MOTU=$ROOT/${c#./}; break; fi
done
if [ -z "$MOTU" ]; then
    command -v cargo >/dev/null ||
        die "no motu binary with \`bench\` (./motu, .dev/bench/motu, .dev/motu, target/release/motu) and no cargo to build one"
    step "building motu (cargo build --release -p motu-cli)"
    cargo build --release -p motu-cli || die "cargo build failed"
    MOTU=$ROOT/target/release/motu
fi
step "motu: $MOTU ($("$MOTU" --version))"

# --- a Vulkan device -------------------------------------------------------------------------
ICD=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
devices_ok() { "$MOTU" devices --json >"$OUT/devices.json" 2>"$OUT/devices.err" && grep -q '"ray_pipeline": true' "$OUT/devices.json"; }
if ! devices_ok && [ -f "$ICD" ] && [ -z "${VK_DRIVER_FILES:-}" ]; then
    step "no ray-tracing device found; using the NVIDIA ICD at $ICD"
    export VK_DRIVER_FILES=$ICD
    export __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
fi
devices_ok || { cat "$OUT/devices.json" "$OUT/devices.err" >&2; die "no Vulkan ray-tracing device: see devices.json"; }
step "motu devices --json"
cat "$OUT/devices.json"

# --- the suite -------------------------------------------------------------------------------
if [ -z "${MOTU_BENCH_COMMIT:-}" ]; then
    if git rev-parse --short HEAD >/dev/null 2>&1; then
        MOTU_BENCH_COMMIT=$(git rev-parse --short HEAD)
        [ -z "$(git status --porcelain --untracked-files=no 2>/dev/null)" ] || MOTU_BENCH_COMMIT+=-dirty
    elif [ -f .dev/bench/COMMIT ]; then
        MOTU_BENCH_COMMIT=$(cat .dev/bench/COMMIT)
    fi
fi
export MOTU_BENCH_COMMIT=${MOTU_BENCH_COMMIT:-unknown}
SCENES=()
for d in .dev/bench/scenes .dev shared/scenes ../shared/scenes; do
    if [ -d "$d/buddha-fractal" ]; then SCENES=(--scenes "$ROOT/$d"); break; fi
done
[ ${#SCENES[@]} -gt 0 ] || echo "note: buddha-fractal not found (.dev/bench/scenes, .dev, shared/scenes): it is left out"
step "motu bench $SUITE (commit $MOTU_BENCH_COMMIT, deadline ${DEADLINE_S} s, work dir $WORK)"
# The deadline counts from here: leave what the setup above took.
LEFT=$((DEADLINE_S - ($(date +%s) - T0)))
[ "$LEFT" -gt 30 ] || LEFT=30
"$MOTU" bench "$SUITE" --work-dir "$WORK" --markdown "$OUT/bench.md" --progress \
    --deadline-s "$LEFT" "${SCENES[@]}" "$@" 2> >(tee "$OUT/bench.log" >&2)
RC=$?
step "motu bench exited with $RC"

# --- results (at most 8 files come back from a device call) -----------------------------------
[ -f "$WORK/bench.json" ] && cp "$WORK/bench.json" "$OUT/bench.json"
tar -C "$WORK" -czf "$OUT/logs.tar.gz" logs 2>/dev/null || true
n=0
for p in "$WORK"/renders/forest-sl.png "$WORK"/renders/forest-ml.png "$WORK"/renders/island-ml.png; do
    if [ -f "$p" ] && [ $n -lt 2 ]; then cp "$p" "$OUT/" && n=$((n + 1)); fi
done
rm -f "$OUT/devices.err"
step "done: $(ls "$OUT" | tr '\n' ' ')in $OUT"
exit $RC
