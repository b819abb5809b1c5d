#!/usr/bin/env bash
# Installs what motu needs on a fresh Debian 12 machine, idempotently:
# Mesa's lavapipe with ray tracing (only bookworm-backports has it: Mesa >= 24.1),
# the Vulkan loader, glslang, spirv-tools, vulkan-tools and validation layers when packaged,
# chromium (report test) and Xvfb with the X libraries winit loads (the `motu view` tests).
# It names no package host: the backports entry reuses the URIs of the existing debian.sources.
set -euo pipefail

log() { printf 'motu-setup: %s\n' "$*" >&2; }

need_root() {
  if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null 2>&1; then SUDO=sudo; else
      log "must run as root (or with sudo) to install packages"; exit 1; fi
  else SUDO=""; fi
}

have_rt_lavapipe() {
  # Mesa >= 24.1 is the first lavapipe with ray tracing.
  local v
  v=$(dpkg-query -W -f='${Version}' mesa-vulkan-drivers 2>/dev/null || true)
  [ -n "$v" ] || return 1
  dpkg --compare-versions "$v" ge 24.1
}

missing=()
command -v glslangValidator >/dev/null 2>&1 || missing+=(glslang-tools)
command -v spirv-val >/dev/null 2>&1 || missing+=(spirv-tools)
command -v vulkaninfo >/dev/null 2>&1 || missing+=(vulkan-tools)
dpkg-query -W -f='${Status}' libvulkan1 2>/dev/null | grep -q "ok installed" || missing+=(libvulkan1)
# The VRAM report's HTML is checked in a real headless browser.
command -v chromium >/dev/null 2>&1 || missing+=(chromium)
# `motu view` is tested in a real window: Xvfb, plus the X libraries winit loads at run time.
command -v Xvfb >/dev/null 2>&1 || missing+=(xvfb)
# ... and on Wayland: a headless weston compositor (it brings libwayland-client and xkbcommon).
command -v weston >/dev/null 2>&1 || missing+=(weston)
for p in libx11-xcb1 libxkbcommon-x11-0 libxcursor1 libxrandr2 libxi6; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "ok installed" || missing+=("$p")
done
backports_needed=0
have_rt_lavapipe || backports_needed=1

if [ ${#missing[@]} -eq 0 ] && [ $backports_needed -eq 0 ]; then
  log "all dependencies present"
  exit 0
fi

if ! command -v apt-get >/dev/null 2>&1; then
  log "missing: ${missing[*]} $( [ $backports_needed -eq 1 ] && echo 'mesa-vulkan-drivers>=24.1' ); no apt-get here: install them by hand"
  exit 1
fi
need_root

src=/etc/apt/sources.list.d/debian.sources
bp=/etc/apt/sources.list.d/motu-backports.sources
if [ ! -f "$bp" ]; then
  uris=""
  if [ -f "$src" ]; then
    uris=$(awk '/^URIs:/ {print $2; exit}' "$src")
  fi
  if [ -z "$uris" ] && [ -f /etc/apt/sources.list ]; then
    uris=$(awk '$1=="deb" && $3 ~ /^bookworm/ {print $2; exit}' /etc/apt/sources.list)
  fi
  if [ -z "$uris" ]; then
    log "cannot find an apt URI to reuse for bookworm-backports in $src"; exit 1
  fi
  log "adding bookworm-backports (reusing the existing mirror)"
  $SUDO tee "$bp" >/dev/null <<EOS
Types: deb
URIs: $uris
Suites: bookworm-backports
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg
EOS
fi

export DEBIAN_FRONTEND=noninteractive
log "apt-get update"
$SUDO apt-get update -qq
pkgs=(libvulkan1 glslang-tools spirv-tools vulkan-tools chromium
  xvfb libx11-xcb1 libxkbcommon-x11-0 libxcursor1 libxrandr2 libxi6 weston)
log "installing ${pkgs[*]} and mesa-vulkan-drivers from bookworm-backports"
$SUDO apt-get install -y -qq --no-install-recommends "${pkgs[@]}" >/dev/null
$SUDO apt-get install -y -qq --no-install-recommends -t bookworm-backports mesa-vulkan-drivers >/dev/null
# Validation layers: packaged in bookworm as vulkan-validationlayers; optional.
if ! dpkg-query -W -f='${Status}' vulkan-validationlayers 2>/dev/null | grep -q "ok installed"; then
  $SUDO apt-get install -y -qq --no-install-recommends vulkan-validationlayers >/dev/null 2>&1 \
    || log "vulkan-validationlayers not available; GPU tests will say validation is off"
fi
have_rt_lavapipe || { log "mesa-vulkan-drivers is still older than 24.1: no ray tracing on lavapipe"; exit 1; }
log "done: $(dpkg-query -W -f='mesa ${Version}' mesa-vulkan-drivers)"
