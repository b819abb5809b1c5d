# Sourced by the device scripts after tools/device-env.sh (which sets MOTU, OUT, W, H, step,
# die): the default `gen island --scale $S` imported with default flags into $WORK (made once,
# reused by later scripts), its report in $OUT/report.json, PEAK (its full build's peak bytes)
# and, when FRACTION is set, BUDGET = PEAK / FRACTION. Sets PKG and SCENE (the pbrt folder).
SCENE=$WORK/island-$S
PKG=$WORK/island-$S.motu
if [ ! -f "$PKG" ] || [ ! -f "$SCENE/cameras/shotCam.pbrt" ]; then
    step "gen island --scale $S; import (default flags)"
    "$MOTU" gen island --scale "$S" -o "$SCENE" --force >/dev/null || die "gen failed"
    /usr/bin/time -v "$MOTU" import "$SCENE/scene.pbrt" -o "$PKG" 2>"$OUT/import.time" >/dev/null ||
        die "import failed"
fi
"$MOTU" report "$PKG" --json --width "$W" --height "$H" >"$OUT/report.json" || die "report failed"
PEAK=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['variants'][0]['cost']['peak_bytes'])" "$OUT/report.json")
if [ -n "${FRACTION:-}" ]; then
    BUDGET=$((PEAK / FRACTION))
    step "peak $PEAK B, budget $BUDGET B (1/$FRACTION)"
else
    step "peak $PEAK B"
fi
