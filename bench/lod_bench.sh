#!/usr/bin/env bash
# Level-of-detail bench: what `info` says each zoom reads, the multi-resolution summary's cost,
# one centre tile per zoom and (optionally) a short `build`, on a 207 Mpixel DEM.
#
#     bench/lod_bench.sh NEW_BIN [OLD_BIN]
#
# NEW_BIN is a terrabound with the summary (74c5fe5 or later); OLD_BIN, if given, one without
# it. Prints TSV lines (first field says what the line is) on stdout; raw logs and /usr/bin/time
# outputs go to $RUNS (default bench/runs/lod, git-ignored). Makes $RUNS/N48W125-x4.tif once:
# N48W125.hgt (from $DATA, default /work/shared/data) resampled 400 % cubic to 14404^2 Int16,
# tiled and deflated, nodata -32768 kept. Needs gdal_translate, unzip, python3, /usr/bin/time.
# Environment: BUILD=1 also runs step 4 (build to coarsest+3; slow), DEADLINE=epoch-seconds
# skips steps that would start after it, NEW_LABEL names NEW's lines (default new), DEM
# overrides the DEM path, POINTS ("lon,lat ...", default the DEM centre -124.5,48.5) the
# tiles' places. Not for CI: it takes many minutes and ~1 GB of RAM.
set -euo pipefail

if [[ $# -lt 1 || $# -gt 2 ]]; then
    sed -n '2,15p' "$0" >&2
    exit 2
fi
NEW=$(realpath "$1")
OLD=${2:+$(realpath "$2")}
HERE=$(cd "$(dirname "$0")" && pwd)
RUNS=${RUNS:-$HERE/runs/lod}
DATA=${DATA:-/work/shared/data}
BUILD=${BUILD:-0}
DEADLINE=${DEADLINE:-0}
POINTS=${POINTS:--124.5,48.5}
mkdir -p "$RUNS"
cd "$RUNS"
DEM=${DEM:-$RUNS/N48W125-x4.tif}
SMALL=$DATA/N44W072.hgt

DATA=$DATA "$HERE/x4_dem.sh" "$DEM"
MPX=$(python3 -c "print(14404 * 14404 / 1e6)")

late() { [[ $DEADLINE -gt 0 && $(date +%s) -ge $DEADLINE ]]; }

# run LOG TIMEFILE CMD...: stderr+stdout of CMD to LOG, each line prefixed with the epoch time
# (microseconds) it was read at; /usr/bin/time -v to TIMEFILE. Returns CMD's exit status.
run() {
    local log=$1 tf=$2 rc=0
    shift 2
    { /usr/bin/time -v -o "$tf" "$@" 2>&1 || echo "EXIT $?"; } |
        while IFS= read -r line; do printf '%s\t%s\n' "$EPOCHREALTIME" "$line"; done >"$log"
    if grep -q $'\tEXIT ' "$log"; then rc=$(grep $'\tEXIT ' "$log" | tail -1 | awk '{print $3}'); fi
    return "$rc"
}
wall() { awk -F': ' '/Elapsed \(wall clock\)/ {n = split($2, p, ":"); s = 0;
    for (i = 1; i <= n; i++) s = s * 60 + p[i]; print s}' "$1"; }
cpu_s() { awk -F': ' '/User time|System time/ {s += $2} END {printf "%.2f", s}' "$1"; }
rss_mb() { awk -F': ' '/Maximum resident set size/ {printf "%.0f", $2 / 1024}' "$1"; }
# seconds between the log's "making its multi-resolution summary" and "summary ready" lines
summary_s() { awk -F'\t' '/making its multi-resolution summary/ && !a {a = $1}
    /summary ready/ && !b {b = $1} END {if (a && b) printf "%.2f", b - a; else print "-"}' "$1"; }
glb_tris() { python3 - "$1" <<'EOF'
import json, struct, sys
d = open(sys.argv[1], "rb").read()
doc = json.loads(d[20:20 + struct.unpack_from("<I", d, 12)[0]])
print(sum(doc["accessors"][p["indices"]]["count"] // 3 for m in doc.get("meshes", []) for p in m["primitives"]))
EOF
}
xy() { python3 -c "import math; s = 180 / 2 ** $1; print(math.floor(($2 + 180) / s), math.floor(($3 + 90) / s))"; }
# zmin zmax of `info`'s pyramid line
zrange() { sed -n 's/.*pyramid:.* zooms \([0-9]*\)\.\.\([0-9]*\).*/\1 \2/p' "$1" | head -1; }

NEW_LABEL=${NEW_LABEL:-new}
BINS=("$NEW_LABEL" "$NEW")
[[ -n $OLD ]] && BINS+=(old "$OLD")

# 1. info: zoom range and per-zoom table
printf 'info\tbin\tdem\tzoom\ttiles\tcolumns\trows\teps_m\treads\n'
printf 'range\tbin\tdem\tzmin\tzmax\twall_s\trss_mb\n'
declare -A ZMIN ZMAX
for ((b = 0; b < ${#BINS[@]}; b += 2)); do
    name=${BINS[b]} bin=${BINS[b + 1]}
    for dem in "$DEM" "$SMALL"; do
        tag=$(basename "$dem")
        out=$RUNS/info-$name-$tag.txt
        run "$out" "$out.time" "$bin" info "$dem" || echo "# $name info $tag failed" >&2
        a=- z=-
        read -r a z < <(zrange "$out") || true
        printf 'range\t%s\t%s\t%s\t%s\t%s\t%s\n' "$name" "$tag" "$a" "$z" "$(wall "$out.time")" \
            "$(rss_mb "$out.time")"
        cut -f2- "$out" | awk -v n="$name" -v t="$tag" \
            '/^ +[0-9]+ +[0-9]+ +[0-9]+ x [0-9]+/ {r = ""; for (i = 7; i <= NF; i++) r = r (i > 7 ? " " : "") $i;
             printf "info\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n", n, t, $1, $2, $3, $5, $6, r}'
        if [[ $dem == "$DEM" ]]; then ZMIN[$name]=$a ZMAX[$name]=$z; fi
    done
done

# 2+3. one tile per zoom at each point (lon,lat); for NEW the coarsest zoom's log gives the
# summary's time (it is built in every run at summary zooms: tile_s = wall_s - summary_s)
printf 'tile\tbin\tlonlat\tzoom\tx\ty\twall_s\tcpu_s\tsummary_s\ttile_s\tsummary_mpx_per_s\trss_mb\tglb_bytes\ttriangles\trc\n'
for pt in $POINTS; do
    lon=${pt%,*} lat=${pt#*,}
    for ((b = 0; b < ${#BINS[@]}; b += 2)); do
        name=${BINS[b]} bin=${BINS[b + 1]}
        [[ ${ZMIN[$name]} == - ]] && continue
        for ((z = ${ZMIN[$name]}; z <= ${ZMAX[$name]}; ++z)); do
            if late; then echo "# deadline: $name tiles at $pt stop before zoom $z" >&2; break; fi
            read -r x y < <(xy "$z" "$lon" "$lat")
            log=$RUNS/tile-$name-$pt-$z.log
            rm -f /tmp/t.glb
            rc=0
            run "$log" "$log.time" "$bin" tile "$DEM" "$z" "$x" "$y" -o /tmp/t.glb || rc=$?
            w=$(wall "$log.time")
            s=$(summary_s "$log")
            if [[ $s == - ]]; then own=$w rate=-; else
                own=$(awk -v w="$w" -v s="$s" 'BEGIN {printf "%.2f", w - s}')
                rate=$(awk -v m="$MPX" -v s="$s" 'BEGIN {printf "%.1f", (s > 0 ? m / s : 0)}')
            fi
            bytes=- tris=-
            if [[ $rc == 0 && -s /tmp/t.glb ]]; then
                bytes=$(stat -c %s /tmp/t.glb) tris=$(glb_tris /tmp/t.glb)
            fi
            printf 'tile\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$name" "$pt" "$z" "$x" \
                "$y" "$w" "$(cpu_s "$log.time")" "$s" "$own" "$rate" "$(rss_mb "$log.time")" \
                "$bytes" "$tris" "$rc"
        done
    done
done

# 4. build to coarsest+3 (BUILD=1)
if [[ $BUILD == 1 ]]; then
    printf 'build\tbin\tzooms\ttiles\twall_s\tcpu_s\ttiles_per_s\trss_mb\trc\n'
    for ((b = 0; b < ${#BINS[@]}; b += 2)); do
        name=${BINS[b]} bin=${BINS[b + 1]}
        top=$((${ZMIN[$NEW_LABEL]} + 3))
        if [[ $name != "$NEW_LABEL" && $top -lt ${ZMIN[$name]} ]]; then
            echo "# $name starts at zoom ${ZMIN[$name]} > $top: no build" >&2
            continue
        fi
        if late; then echo "# deadline: no $name build" >&2; continue; fi
        out=/tmp/lodout-$name
        rm -rf "$out"
        log=$RUNS/build-$name.log
        rc=0
        run "$log" "$log.time" "$bin" build "$DEM" -o "$out" --layer terrain --formats glb --threads 2 \
            --max-zoom "$top" || rc=$?
        w=$(wall "$log.time")
        n=$(find "$out" -name '*.glb' | wc -l)
        printf 'build\t%s\t..%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$name" "$top" "$n" "$w" "$(cpu_s "$log.time")" \
            "$(awk -v n="$n" -v w="$w" 'BEGIN {printf "%.2f", (w > 0 ? n / w : 0)}')" \
            "$(rss_mb "$log.time")" "$rc"
        [[ -d $out/terrain ]] && python3 "$HERE/pyramid_stats.py" "$out/terrain" | sed "s/^/stats\t$name\t/"
    done
fi
