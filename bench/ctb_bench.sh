#!/usr/bin/env bash
# Globe terrain against a peer, in one run: Terrabound's quantized-mesh pyramid
# (`build --formats terrain`) and cesium-terrain-builder's (`ctb-tile -f Mesh`) on the same DEM
# and the same zooms: build time (wall, CPU, tiles/s, peak RSS), per zoom the tiles, gzip bytes,
# triangles and the error against every source pixel, Terrabound's measured/published bound
# per zoom, and a cold `terrabound tile` per zoom.
#
#     bench/ctb_bench.sh TB_BIN [DEM]          # DEM default $DATA/N44W072.hgt; .zip is unzipped
#
# TB_BIN is a Release terrabound. cesium-terrain-builder is not part of the project: build it
# outside the repository (bench/README.md, "Globe terrain beside cesium-terrain-builder") and
# point CTB at its ctb-tile (default /work/peers/ctb/build/tools/ctb-tile; its libctb is looked
# for in ../src). Environment: RUNS (outputs, default bench/runs/ctb, git-ignored), DATA
# (default /work/shared/data), MAX_ZOOM (finest zoom of both; default Terrabound's own),
# THREADS (both, default 2), REPS (builds, alternating who goes first, each printed; default
# 1), TIMEOUT (seconds per build, default 1800), CTB_NATIVE=1 (also ctb to its own finest zoom),
# STEPS (default "build stats tiles"; "stats tiles" judges the pyramids a previous run left in
# $RUNS), TILES=0 (no cold tiles), POINT (lon,lat of the cold tiles, default the DEM's centre),
# GEOID (default /usr/share/proj/egm96_15.gtx), CTB_NORMALS=1 (ctb also writes vertex normals,
# -N; by default it does not, as Terrabound's static tiles carry no normals: only its metadata
# extension). Both store their tiles gzip-compressed. Needs gdal-bin, node, python3, /usr/bin/time.
# Prints TSV lines on stdout, the first field saying what the line is; logs go to $RUNS.
set -euo pipefail

if [[ $# -lt 1 || $# -gt 2 ]]; then
    sed -n '2,23p' "$0" >&2
    exit 2
fi
TB=$(realpath "$1")
HERE=$(cd "$(dirname "$0")" && pwd)
DATA=${DATA:-/work/shared/data}
SRC=$(realpath "${2:-$DATA/N44W072.hgt}")
RUNS=${RUNS:-$HERE/runs/ctb}
CTB=${CTB:-/work/peers/ctb/build/tools/ctb-tile}
THREADS=${THREADS:-2}
REPS=${REPS:-1}
TIMEOUT=${TIMEOUT:-1800}
TILES=${TILES:-1}
STEPS=" ${STEPS:-build stats tiles} "
GEOID=${GEOID:-/usr/share/proj/egm96_15.gtx}
CTB_NATIVE=${CTB_NATIVE:-0}
CTB_NORMALS=${CTB_NORMALS:-0}
CTB_FLAGS=(-f Mesh -C)
[[ $CTB_NORMALS == 1 ]] && CTB_FLAGS+=(-N)
for tool in gdalinfo gdal_translate node python3 /usr/bin/time "$CTB"; do
    command -v "$tool" >/dev/null || { echo "ctb_bench: $tool not found" >&2; exit 2; }
done
export LD_LIBRARY_PATH=$(dirname "$(dirname "$(realpath "$CTB")")")/src${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
mkdir -p "$RUNS"
RUNS=$(realpath "$RUNS")

# The DEM as both tools read it (a .zip unzipped into $RUNS) and as raw float32 for the checker.
tag=$(basename "$SRC")
tag=${tag%.zip}
tag=${tag%.*}
W=$RUNS/$tag
mkdir -p "$W"
DEM=$SRC
if [[ $SRC == *.zip ]]; then
    unzip -o -q "$SRC" -d "$W/src"
    DEM=$(find "$W/src" -type f | head -1)
fi
RAW=$W/dem.f32
if [[ ! -s $RAW || $RAW -ot $DEM ]]; then
    gdal_translate -q -of ENVI -ot Float32 "$DEM" "$RAW"
fi

# run LOG TIMEFILE CMD...: CMD's output to LOG, /usr/bin/time -v to TIMEFILE, under $TIMEOUT.
run() {
    local log=$1 tf=$2
    shift 2
    /usr/bin/time -v -o "$tf" timeout "$TIMEOUT" "$@" >"$log" 2>&1
}
wall() { awk -F': ' '/Elapsed \(wall clock\)/ {n = split($2, p, ":"); s = 0;
    for (i = 1; i <= n; i++) s = s * 60 + p[i]; print s}' "$1"; }
cpu_s() { awk -F': ' '/User time|System time/ {s += $2} END {printf "%.2f", s}' "$1"; }
rss_mb() { awk -F': ' '/Maximum resident set size/ {printf "%.0f", $2 / 1024}' "$1"; }
load1() { cut -d' ' -f1 /proc/loadavg; }
count() { find "$1" -name '*.terrain' | wc -l; }
maxzoom() { python3 -c "import json, sys; print(json.load(open(sys.argv[1]))['maxzoom'])" "$1"; }

printf 'dem\t%s\t%s\tmpx\t%s\tload1\t%s\tnproc\t%s\n' "$tag" "$DEM" \
    "$(gdalinfo -json "$DEM" | python3 -c 'import json, sys; s = json.load(sys.stdin)["size"]; print(s[0] * s[1] / 1e6)')" \
    "$(load1)" "$(nproc)"

# Terrabound's finest terrain zoom, unless MAX_ZOOM says: from its first build's layer.json.
TB_OUT=$W/tb
CTB_OUT=$W/ctb
ZMAX=${MAX_ZOOM:-}
step() { [[ $STEPS == *" $1 "* ]]; }
printf 'build\tlabel\tzooms\ttiles\twall_s\tcpu_s\ttiles_per_s\trss_mb\tload1_before\tload1_after\trc\trep\n'
build_tb() {
    local rep=$1 rc=0 before
    rm -rf "$TB_OUT"
    before=$(load1)
    run "$W/tb-build.log" "$W/tb-build.time" "$TB" build "$DEM" -o "$TB_OUT" \
        --layer terrain --formats terrain --threads "$THREADS" ${ZMAX:+--max-zoom "$ZMAX"} || rc=$?
    [[ -z $ZMAX && -s $TB_OUT/terrain/layer.json ]] && ZMAX=$(maxzoom "$TB_OUT/terrain/layer.json")
    report terrabound "$W/tb-build.time" "$(count "$TB_OUT")" "$before" "$rc" "$rep"
}
# ctb-tile OUT START: tiles, then (untimed) its layer.json
build_ctb() {
    local label=$1 out=$2 start=$3 rep=$4 rc=0 before
    rm -rf "$out"
    mkdir -p "$out"
    before=$(load1)
    run "$W/$label-build.log" "$W/$label-build.time" "$CTB" "${CTB_FLAGS[@]}" -c "$THREADS" \
        ${start:+-s "$start"} -e 0 -o "$out" "$DEM" || rc=$?
    "$CTB" -q "${CTB_FLAGS[@]}" ${start:+-s "$start"} -e 0 -l -o "$out" "$DEM" >/dev/null 2>&1 || true
    report "$label" "$W/$label-build.time" "$(count "$out")" "$before" "$rc" "$rep"
}
report() { # label timefile tiles load_before rc rep
    local w
    w=$(wall "$2")
    printf 'build\t%s\t0..%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$1" "${ZMAX:--}" "$3" "$w" \
        "$(cpu_s "$2")" "$(awk -v n="$3" -v w="$w" 'BEGIN {printf "%.1f", (w > 0 ? n / w : 0)}')" \
        "$(rss_mb "$2")" "$4" "$(load1)" "$5" "$6"
    [[ $5 == 0 ]] || echo "# $1 build exited $5 (124: over TIMEOUT=$TIMEOUT s); see $W" >&2
}
step build || REPS=0
if ! step build && [[ -z $ZMAX && -s $TB_OUT/terrain/layer.json ]]; then ZMAX=$(maxzoom "$TB_OUT/terrain/layer.json"); fi
for ((rep = 1; rep <= REPS; ++rep)); do
    # alternate who goes first, so that both see the same load on average
    if ((rep % 2)); then build_tb "$rep"; build_ctb ctb "$CTB_OUT" "$ZMAX" "$rep"
    else build_ctb ctb "$CTB_OUT" "$ZMAX" "$rep"; build_tb "$rep"; fi
done
if [[ $CTB_NATIVE == 1 ]] && step build; then
    build_ctb ctb-native "$W/ctb-native" "" 1
fi

# Per zoom: weight, triangles, error against every source pixel (Terrabound's heights are above
# the ellipsoid: the checker adds EGM96 to the pixels; ctb's are the DEM's own values).
stats() { # label dir [--geoid G]
    local label=$1 dir=$2
    shift 2
    node "$HERE/qm_stats.mjs" "$dir" --label "$label" --dem "$DEM" --raw "$RAW" \
        --tiles "$W/$label-tiles.tsv" "$@" | tail -n +2 | sed 's/^/zoom\t/'
}
if step stats; then
printf 'zoom\tlabel\tzoom\ttiles\tgzip_kb_total\tgzip_kb_median\tgzip_kb_max\tmesh_gzip_kb_median\ttri_median\ttri_max\tdata_tiles\terr_median\terr_max\tpixels\tuncovered\tpub_median\tratio_median\tratio_max\ttri_median_data\tgzip_kb_median_data\tinner_err_median\tinner_err_max\n'
stats terrabound "$TB_OUT/terrain" --geoid "$GEOID"
stats ctb "$CTB_OUT"
if [[ $CTB_NATIVE == 1 && -d $W/ctb-native ]]; then stats ctb-native "$W/ctb-native"; fi

# Totals over the same zooms (the gzip -6 bytes of every tile; on disk both store gzip).
printf 'total\tlabel\ttiles\tgzip_kb\tbytes_on_disk_kb\n'
for pair in "terrabound:$TB_OUT/terrain" "ctb:$CTB_OUT"; do
    label=${pair%%:*} dir=${pair#*:}
    printf 'total\t%s\t%s\t%s\t%s\n' "$label" "$(count "$dir")" \
        "$(awk -F'\t' -v l="$label" '$1 == l {s += $7} END {printf "%.0f", s / 1024}' "$W/$label-tiles.tsv")" \
        "$(find "$dir" -name '*.terrain' -printf '%s\n' | awk '{s += $1} END {printf "%.0f", s / 1024}')"
done
fi

# A cold tile per zoom (a new process each, no tile cache; the OS file cache is warm): Terrabound
# only, ctb has no single-tile command. `tile` writes the zoom's 3D Tiles glb.
if [[ $TILES == 1 ]] && step tiles; then
    read -r clon clat < <(gdalinfo -json "$DEM" | python3 -c 'import json, sys
c = json.load(sys.stdin)["cornerCoordinates"]
print((c["upperLeft"][0] + c["lowerRight"][0]) / 2, (c["upperLeft"][1] + c["lowerRight"][1]) / 2)')
    if [[ -n ${POINT:-} ]]; then clon=${POINT%,*} clat=${POINT#*,}; fi
    printf 'tile\tlabel\tzoom\tx\ty\twall_s\tcpu_s\trss_mb\tglb_bytes\trc\n'
    for ((z = 0; z <= ZMAX; ++z)); do
        read -r x y < <(python3 -c "import math; s = 180 / 2 ** $z; print(math.floor(($clon + 180) / s), math.floor(($clat + 90) / s))")
        rc=0
        rm -f "$W/tile.glb"
        run "$W/tile-$z.log" "$W/tile-$z.time" "$TB" tile "$DEM" "$z" "$x" "$y" -o "$W/tile.glb" || rc=$?
        printf 'tile\tterrabound\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$z" "$x" "$y" "$(wall "$W/tile-$z.time")" \
            "$(cpu_s "$W/tile-$z.time")" "$(rss_mb "$W/tile-$z.time")" \
            "$( [[ -s $W/tile.glb ]] && stat -c %s "$W/tile.glb" || echo -)" "$rc"
    done
fi
printf 'end\tload1\t%s\n' "$(load1)"
