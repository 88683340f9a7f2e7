#!/usr/bin/env bash
# What a CesiumJS client fetches, Terrabound's static quantized-mesh pyramid against
# cesium-terrain-builder's: per fixed view, the terrain requests, bytes on the wire and zooms
# asked, from headless Chromium with CesiumTerrainProvider at its default maximumScreenSpaceError
# (bench/client_bench.mjs prints the TSV; it serves every pyramid the same way: gzip .terrain
# with Content-Encoding: gzip, over loopback, a cold browser cache per view).
#
#     bench/client_bench.sh TB_BIN [DEM]         # DEM default $DATA/N44W072.hgt
#
# TB_BIN is a Release terrabound. The pyramids (in $RUNS/DEM/, default bench/runs/client,
# git-ignored) are made once and reused (REBUILD=1 makes them again): `terrabound build DEM
# --layer terrain --formats terrain` (to its own finest zoom), ctb to its own default finest zoom
# (`ctb-tile -f Mesh -C`, no normals: Terrabound's static tiles carry none) and, with
# CTB_LIMITED=1 (default), ctb again to Terrabound's finest zoom (`-s Z`). cesium-terrain-builder
# is not part of the project: build it outside the repository (bench/README.md) and point CTB at
# its ctb-tile (default /work/peers/ctb/build/tools/ctb-tile; libctb looked for in ../src).
# Environment: VIEWS ("NAME:LON,LAT,HEIGHT,PITCH;...": camera HEIGHT m above the ellipsoid,
# looking at LON,LAT from PITCH degrees below the horizon; default three views of N44W072: the
# whole DEM, Crawford Notch, Mount Washington), TIMEOUT (s per view, default 240), DATA (default
# /work/shared/data). Needs node, web/node_modules (npm ci --prefix web) and /usr/bin/chromium.
set -euo pipefail

if [[ $# -lt 1 || $# -gt 2 ]]; then
    sed -n '2,20p' "$0" >&2
    exit 2
fi
TB=$(realpath "$1")
HERE=$(cd "$(dirname "$0")" && pwd)
DATA=${DATA:-/work/shared/data}
SRC=$(realpath "${2:-$DATA/N44W072.hgt}")
RUNS=${RUNS:-$HERE/runs/client}
CTB=${CTB:-/work/peers/ctb/build/tools/ctb-tile}
CTB_LIMITED=${CTB_LIMITED:-1}
REBUILD=${REBUILD:-0}
TIMEOUT=${TIMEOUT:-240}
# The whole DEM from 160 km straight down; Crawford Notch (a valley, floor ~550 m) from 6 km at
# 35 degrees; Mount Washington's summit (1,917 m) from 2.8 km at 25 degrees.
N44W072_VIEWS='whole:-71.5,44.5,160000,90;valley:-71.41,44.21,6000,35;close:-71.3033,44.2706,2800,25'
tag=$(basename "$SRC")
tag=${tag%.zip}
tag=${tag%.*}
if [[ -z ${VIEWS:-} ]]; then
    [[ $tag == N44W072 ]] || { echo "client_bench: set VIEWS for $tag" >&2; exit 2; }
    VIEWS=$N44W072_VIEWS
fi
for tool in node "$CTB" /usr/bin/chromium; do
    command -v "$tool" >/dev/null || { echo "client_bench: $tool not found" >&2; exit 2; }
done
export LD_LIBRARY_PATH=$(dirname "$(dirname "$(realpath "$CTB")")")/src${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
W=$RUNS/$tag
mkdir -p "$W"
W=$(realpath "$W")
DEM=$SRC
if [[ $SRC == *.zip ]]; then
    unzip -o -q "$SRC" -d "$W/src"
    DEM=$(find "$W/src" -type f | head -1)
fi
load1() { cut -d' ' -f1 /proc/loadavg; }
maxzoom() { python3 -c "import json, sys; print(json.load(open(sys.argv[1]))['maxzoom'])" "$1"; }

# ctb OUT [START]: tiles, then its layer.json
ctb() {
    rm -rf "$1"
    mkdir -p "$1"
    "$CTB" -q -f Mesh -C ${2:+-s "$2"} -o "$1" "$DEM" >"$1.log" 2>&1
    "$CTB" -q -f Mesh -C ${2:+-s "$2"} -l -o "$1" "$DEM" >>"$1.log" 2>&1
}
if [[ $REBUILD == 1 || ! -s $W/tb/terrain/layer.json ]]; then
    rm -rf "$W/tb"
    "$TB" build "$DEM" -o "$W/tb" --layer terrain --formats terrain >"$W/tb.log" 2>&1
fi
ZMAX=$(maxzoom "$W/tb/terrain/layer.json")
if [[ $REBUILD == 1 || ! -s $W/ctb/layer.json ]]; then ctb "$W/ctb"; fi
if [[ $CTB_LIMITED == 1 && ($REBUILD == 1 || ! -s $W/ctb-z$ZMAX/layer.json) ]]; then
    ctb "$W/ctb-z$ZMAX" "$ZMAX"
fi

printf 'dem\t%s\t%s\tterrabound_maxzoom\t%s\tload1\t%s\tnproc\t%s\n' "$tag" "$DEM" "$ZMAX" "$(load1)" "$(nproc)"
pyramids=("terrabound=$W/tb/terrain" "ctb=$W/ctb")
if [[ $CTB_LIMITED == 1 ]]; then pyramids+=("ctb-z$ZMAX=$W/ctb-z$ZMAX"); fi
node "$HERE/client_bench.mjs" --timeout "$TIMEOUT" --views "$VIEWS" "${pyramids[@]}"
printf 'end\tload1\t%s\n' "$(load1)"
