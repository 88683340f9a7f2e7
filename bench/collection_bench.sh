#!/usr/bin/env bash
# Collection bench: one DEM as one file against the same pixels cut into SIDE x SIDE files
# (gdal_translate -srcwin), read as one collection (a directory). Same binary, same run.
#
#     bench/collection_bench.sh [BIN]
#
# BIN: a terrabound binary (default: a Release one built in build-bench/). DEM: the DEM to cut
# (default bench/runs/lod/N48W125-x4.tif, 14404^2, made once by x4_dem.sh); SIDE: files per side
# (default 32: 1,024 files); PER_ZOOM: cold tiles per zoom (default 8); FORMAT: tile format
# (default glb); RUNS: where the cut files and summaries are kept (default
# bench/runs/collection, git-ignored). Cases, one TSV line each on stdout (logs on stderr):
#   info     `terrabound info`: wall seconds and peak RSS, first run (makes the summary) and again
#            (reuses it);
#   serve    `serve` from start to /health answering (the summary already made), RSS and open
#            file descriptors then;
#   cold     per zoom, the same PER_ZOOM tiles (seeded, over the data's bounds) requested for the
#            first time, one after another on one connection: p50/p99 ms, and how many of them
#            are byte-identical between the two servers;
#   after    RSS, peak RSS and open file descriptors of each server after its cold tiles.
# Needs gdal_translate (or, much faster for thousands of files, GDAL's Python bindings:
# apt-get install python3-gdal), curl, python3, /usr/bin/time. Not for CI: minutes, and ~1 GB of RAM.
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
ROOT=$(dirname "$HERE")
log() { printf '%s collection_bench: %s\n' "$(date -u +%FT%TZ)" "$*" >&2; }
die() { log "$*"; exit 1; }
for tool in gdal_translate curl python3; do
    command -v "$tool" >/dev/null || die "$tool is missing; apt-get install -y gdal-bin curl"
done

BIN=${1:-}
if [[ -z $BIN ]]; then
    cmake -S "$ROOT" -B "$ROOT/build-bench" -DCMAKE_BUILD_TYPE=Release -DTB_BUILD_TESTS=OFF >/dev/null
    cmake --build "$ROOT/build-bench" --target terrabound -j2 >/dev/null
    BIN=$ROOT/build-bench/terrabound
fi
BIN=$(realpath "$BIN")
RUNS=${RUNS:-$HERE/runs/collection}
DEM=${DEM:-$HERE/runs/lod/N48W125-x4.tif}
SIDE=${SIDE:-32}
PER_ZOOM=${PER_ZOOM:-8}
FORMAT=${FORMAT:-glb}
mkdir -p "$RUNS"
"$HERE/x4_dem.sh" "$DEM"
DEM=$(realpath "$DEM")

# ---- the cut: SIDE x SIDE windows covering the DEM, made once ----
CUT=$RUNS/cut-$(basename "$DEM" .tif)-$SIDE
if [[ ! -f $CUT/.complete ]]; then
    rm -rf "$CUT"
    mkdir -p "$CUT"
    log "cutting $DEM into $SIDE x $SIDE files in $CUT"
    start=$(date +%s.%N)
    read -r W H < <(python3 -c 'import json,sys; print(*json.load(sys.stdin)["size"])' \
        < <(gdalinfo -json "$DEM"))
    windows() {
        python3 -c '
import sys
w, h, n, dem, cut = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], sys.argv[5]
xs = [w * i // n for i in range(n + 1)]
ys = [h * j // n for j in range(n + 1)]
for j in range(n):
    for i in range(n):
        print(dem, xs[i], ys[j], xs[i + 1] - xs[i], ys[j + 1] - ys[j], f"{cut}/r{j:03d}_c{i:03d}.tif")
' "$W" "$H" "$SIDE" "$DEM" "$CUT"
    }
    if /usr/bin/python3 -c 'import osgeo.gdal' 2>/dev/null; then
        # GDAL's Python bindings (Debian: python3-gdal) cut in one process: 10,000 files in
        # minutes rather than the better part of an hour of gdal_translate processes.
        windows | /usr/bin/python3 -c '
import sys
from osgeo import gdal
gdal.UseExceptions()
src = None
for line in sys.stdin:
    dem, x, y, w, h, out = line.split()
    src = src or gdal.Open(dem)
    gdal.Translate(out, src, srcWin=[int(x), int(y), int(w), int(h)],
                   creationOptions=["TILED=YES", "COMPRESS=DEFLATE"])
'
    else
        windows | xargs -P 2 -L 1 sh -c 'gdal_translate -q -srcwin "$1" "$2" "$3" "$4" \
            -co TILED=YES -co COMPRESS=DEFLATE "$0" "$5"'
    fi
    CUT_S=$(python3 -c "import time; print(f'{time.time() - $start:.1f}')")
    echo "$CUT_S" >"$CUT/.complete"
fi
FILES=$(find "$CUT" -name '*.tif' | wc -l)
log "$FILES files in $CUT (cut in $(cat "$CUT/.complete") s)"

WORK=$(mktemp -d /tmp/tb_collection_bench.XXXXXX)
PIDS=()
cleanup() {
    for pid in "${PIDS[@]}"; do kill "$pid" 2>/dev/null || true; done
    wait 2>/dev/null || true
    rm -rf "$WORK"
}
trap cleanup EXIT

declare -A INPUT=([one]=$DEM [collection]=$CUT)
wall() { awk -F': ' '/Elapsed \(wall clock\)/ {n = split($2, p, ":"); s = 0;
    for (i = 1; i <= n; i++) s = s * 60 + p[i]; print s}' "$1"; }
rss_mb() { awk -F': ' '/Maximum resident set size/ {printf "%.0f", $2 / 1024}' "$1"; }
proc_mb() { awk -v k="$2:" '$1 == k {printf "%.0f", $2 / 1024}' "/proc/$1/status"; }
fds() { find "/proc/$1/fd" -mindepth 1 -maxdepth 1 2>/dev/null | wc -l; }
zooms() { sed -n 's/.*pyramid:.* zooms \([0-9]*\)\.\.\([0-9]*\).*/\1..\2/p' "$1" | head -1; }

# ---- info: first run makes each case's summary in RUNS/summaries-CASE, the second reuses it ----
printf 'info\tcase\tfiles\trun\twall_s\trss_mb\tzooms\n'
for c in one collection; do
    rm -rf "$RUNS/summaries-$c"
    mkdir -p "$RUNS/summaries-$c"
    n=1
    [[ $c == collection ]] && n=$FILES
    for run in first again; do
        out=$WORK/info-$c-$run
        /usr/bin/time -v -o "$out.time" "$BIN" info "${INPUT[$c]}" \
            --summary-dir "$RUNS/summaries-$c" >"$out.txt" 2>"$out.log" ||
            die "info of $c failed: $(tail -3 "$out.log")"
        printf 'info\t%s\t%s\t%s\t%s\t%s\t%s\n' "$c" "$n" "$run" "$(wall "$out.time")" \
            "$(rss_mb "$out.time")" "$(zooms "$out.txt")"
    done
done

free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
declare -A PORT PID
printf 'serve\tcase\tstart_s\trss_mb\tfds\n'
for c in one collection; do
    cat >"$WORK/$c.json" <<EOF
{"server": {"threads": 2, "log_level": "warn"},
 "layers": [{"name": "bench", "sources": ["${INPUT[$c]}"], "formats": ["$FORMAT"],
             "summary_dir": "$RUNS/summaries-$c", "store": null}]}
EOF
    PORT[$c]=$(free_port)
    start=$(date +%s.%N)
    "$BIN" serve "$WORK/$c.json" --port "${PORT[$c]}" 2>"$WORK/serve-$c.log" &
    PID[$c]=$!
    PIDS+=("${PID[$c]}")
    until curl -fs "http://127.0.0.1:${PORT[$c]}/health" >/dev/null 2>&1; do
        kill -0 "${PID[$c]}" 2>/dev/null || die "serve of $c exited: $(tail -3 "$WORK/serve-$c.log")"
        sleep 0.02
    done
    up=$(python3 -c "import time; print(f'{time.time() - $start:.2f}')")
    printf 'serve\t%s\t%s\t%s\t%s\n' "$c" "$up" "$(proc_mb "${PID[$c]}" VmRSS)" "$(fds "${PID[$c]}")"
done

# The same seeded tiles of each zoom for both cases, from the one-file layer's /layers.
curl -fs "http://127.0.0.1:${PORT[one]}/layers" | python3 -c '
import json, math, random, sys
per_zoom, fmt = int(sys.argv[1]), sys.argv[2]
layer = json.load(sys.stdin)["layers"][0]
b = layer["bounds"]
for z in range(layer["min_zoom"], layer["max_zoom"] + 1):
    size = 180.0 / 2**z   # geodetic: 2 x 1 tiles at z = 0, y from the south
    e = 1e-9
    x0, x1 = math.floor((b["west"] + 180) / size + e), math.ceil((b["east"] + 180) / size - e) - 1
    y0, y1 = math.floor((b["south"] + 90) / size + e), math.ceil((b["north"] + 90) / size - e) - 1
    tiles = [(x, y) for x in range(x0, x1 + 1) for y in range(y0, y1 + 1)]
    random.Random(z).shuffle(tiles)
    for x, y in tiles[:per_zoom]:
        print(z, f"/bench/{z}/{x}/{y}.{fmt}")
' "$PER_ZOOM" "$FORMAT" >"$WORK/tiles.txt"

percentiles() {  # stdin: seconds, one per line -> "p50_ms p99_ms"
    python3 -c '
import sys
v = sorted(float(l) * 1000 for l in sys.stdin if l.strip())
def q(p): return v[min(len(v) - 1, int(round(p * (len(v) - 1))))]
print(f"{q(0.5):.1f}\t{q(0.99):.1f}")'
}

printf 'cold\tzoom\ttiles\tone_p50_ms\tone_p99_ms\tcollection_p50_ms\tcollection_p99_ms\tidentical\tstatus\n'
for z in $(cut -d' ' -f1 "$WORK/tiles.txt" | uniq); do
    declare -A STATS=()
    for c in one collection; do
        mkdir -p "$WORK/tiles-$c"
        : >"$WORK/cold-$c-$z.out"
        while read -r zz path; do
            [[ $zz == "$z" ]] || continue
            curl -s -o "$WORK/tiles-$c/$(echo "$path" | tr / _)" -w '%{http_code} %{time_total}\n' \
                "http://127.0.0.1:${PORT[$c]}$path" >>"$WORK/cold-$c-$z.out"
        done <"$WORK/tiles.txt"
        STATS[$c]=$(cut -d' ' -f2 "$WORK/cold-$c-$z.out" | percentiles)
    done
    same=0 n=0
    while read -r zz path; do
        [[ $zz == "$z" ]] || continue
        f=$(echo "$path" | tr / _)
        n=$((n + 1))
        cmp -s "$WORK/tiles-one/$f" "$WORK/tiles-collection/$f" && same=$((same + 1))
    done <"$WORK/tiles.txt"
    codes=$(cut -d' ' -f1 "$WORK/cold-one-$z.out" "$WORK/cold-collection-$z.out" | sort | uniq -c |
        awk '{printf "%s%s:%s", (NR > 1 ? "," : ""), $2, $1}')
    printf 'cold\t%s\t%s\t%s\t%s\t%s/%s\t%s\n' "$z" "$n" "${STATS[one]}" "${STATS[collection]}" \
        "$same" "$n" "$codes"
done

printf 'after\tcase\trss_mb\tpeak_rss_mb\tfds\n'
for c in one collection; do
    printf 'after\t%s\t%s\t%s\t%s\n' "$c" "$(proc_mb "${PID[$c]}" VmRSS)" \
        "$(proc_mb "${PID[$c]}" VmHWM)" "$(fds "${PID[$c]}")"
done
