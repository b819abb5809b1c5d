# Sourced by the device scripts (stream-device.sh, speed-device.sh) after they set ROOT (the
# repository), NAME, SIZE (WxH), OUT and WORK: W and H, the two folders, `step` (a timed line,
# also in $OUT/summary.txt) and `die`; the Vulkan loader from .gl/*.deb when the machine has
# none, the NVIDIA ICD when no driver is found, and $MOTU, a release binary: $MOTU_BIN when set
# (an A/B of two binaries), else ./motu, .dev/motu, .dev/bench/motu or target/release/motu.
W=${SIZE%x*}
H=${SIZE#*x}
mkdir -p "$OUT" "$WORK"
T0=$(date +%s)
step() { echo "== [$(($(date +%s) - T0)) s] $*" | tee -a "$OUT/summary.txt"; }
die() { echo "$NAME: $*" >&2; exit 1; }
if ! ldconfig -p | grep -q 'libvulkan\.so\.1' && compgen -G "$ROOT/.gl/*.deb" >/dev/null; then
    for f in "$ROOT"/.gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
fi
ICD=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
if [ -f "$ICD" ] && [ -z "${VK_DRIVER_FILES:-}" ]; then
    export VK_DRIVER_FILES=$ICD
    export __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
fi
MOTU=${MOTU_BIN:-}
for c in motu .dev/motu .dev/bench/motu target/release/motu; do
    [ -z "$MOTU" ] || break
    if [ -x "$ROOT/$c" ]; then MOTU=$ROOT/$c; break; fi
done
[ -n "$MOTU" ] || die "no release binary (./motu, .dev/motu, .dev/bench/motu, target/release/motu)"
