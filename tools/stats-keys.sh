#!/bin/bash
# The JSON keys of a fixed list of invocations (render: cpu, pipeline, query, denoise, stream,
# camera path, LOD; view full and streamed under Xvfb; info, devices, report, import), one
# OUTDIR/NAME.keys file of "key.path type" lines each, and their exit codes in OUTDIR/rc.txt.
# Issue 46 acceptance: run it with the binaries before and after a change and compare:
#   tools/stats-keys.sh OLD/motu /tmp/a; tools/stats-keys.sh NEW/motu /tmp/b
#   for f in /tmp/a/*.keys; do comm -23 $f /tmp/b/$(basename $f); done   # lost keys: none
# usage: stats-keys.sh MOTU OUTDIR (scenes are made once in $STATS_WORK, default /tmp/stats-work)
set -u
M=$1; O=$2; mkdir -p "$O"; W=${STATS_WORK:-/tmp/stats-work}; mkdir -p "$W"
export MOTU_VALIDATION=1
if [ ! -f $W/forest.motu ]; then
  $M gen forest -o $W/forest --levels 2 --grid 3x2 --leaves 60 >/dev/null 2>&1
  $M import $W/forest/scene.pbrt -o $W/forest.motu >/dev/null 2>&1
  $M gen lod-grid -o $W/grid >/dev/null 2>&1 || true
  $M import $W/grid/scene.pbrt -o $W/grid.motu --lod 3 >/dev/null 2>&1 || true
fi
P=$W/forest.motu
R="$M render $P --width 32 --height 18"
run() { name=$1; shift; "$@" > $O/$name.stdout 2> $O/$name.stderr; echo "$name rc=$?" >> $O/rc.txt; }
: > $O/rc.txt
run cpu $R -o $O/cpu.png --backend cpu --stats $O/cpu.json
run cpu_frames $R -o $O/cpuf.png --backend cpu --frames 2 --stats $O/cpu_frames.json
run pipeline $R -o $O/pipe.png --backend pipeline --stats $O/pipeline.json
run query $R -o $O/query.png --backend query --stats $O/query.json
run denoise $R -o $O/den.png --backend pipeline --denoise --stats $O/denoise.json
run stream $R -o $O/stream.png --backend pipeline --stream --frames 2 --stats $O/stream.json
run stream_cache $R -o $O/streamc.png --backend pipeline --stream --as-cache $W/cache --frames 2 --stats $O/stream_cache.json
run cpu_lod $M render $W/grid.motu --width 32 --height 18 -o $O/gl.png --backend cpu --stats $O/cpu_lod.json
run gpu_lod $M render $W/grid.motu --width 32 --height 18 -o $O/gg.png --backend pipeline --stats $O/gpu_lod.json
run info $M info $P --json
run devices $M devices --json
run report $M report $P --json --budget 64MiB
run import $M import $W/forest/scene.pbrt -o $W/forest2.motu --json
cat > $W/path.json <<'J'
{"format":"motu-camera-path","version":1,"width":32,"height":18,"frames":[
 {"eye":[30,20,30],"forward":[-0.6,-0.4,-0.6],"up":[0,1,0],"fov_deg":45},
 {"eye":[31,20,30],"forward":[-0.6,-0.4,-0.6],"up":[0,1,0],"fov_deg":45}]}
J
run path $M render $P -o $O/path.png --backend pipeline --camera-path $W/path.json --stats $O/path.json
run path_cpu $M render $P -o $O/pathc.png --backend cpu --camera-path $W/path.json --stats $O/path_cpu.json
run view xvfb-run -a $M view $P --width 32 --height 18 --frames 2 --stats $O/view.json
run view_stream xvfb-run -a $M view $P --width 32 --height 18 --frames 2 --stream --stats $O/view_stream.json
for n in info devices report import; do cp $O/$n.stdout $O/$n.out.json; done
# key paths with JSON types
python3 - "$O" <<'PY'
import json, sys, glob, os
o = sys.argv[1]
def walk(v, p, out):
    t = type(v).__name__
    if isinstance(v, dict):
        out.add((p, 'object'))
        for k, x in v.items(): walk(x, p + '.' + k if p else k, out)
    elif isinstance(v, list):
        out.add((p, 'array'))
        for x in v: walk(x, p + '[]', out)
    else:
        out.add((p, {'bool':'bool','int':'int','float':'float','str':'string','NoneType':'null'}[t]))
for f in sorted(glob.glob(o + '/*.json')):
    try: v = json.load(open(f))
    except Exception as e: print('bad', f, e); continue
    out = set(); walk(v, '', out)
    with open(f[:-5] + '.keys', 'w') as k:
        for p, t in sorted(out): k.write(f'{p} {t}\n')
PY
