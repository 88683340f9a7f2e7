#!/usr/bin/env bash
# Benchmark of `terrabound build`: whole pyramids at default settings, 1 and 2 threads.
# One TSV line per case:
#   input  threads  zooms  tiles  wall_s  tiles_per_s  peak_rss_mb  out_bytes
# Inputs (why each is here):
#   N48W125.hgt.zip  3601x3601 SRTM1, half ocean (nodata): the large case
#   N44W072.hgt      1201x1201 SRTM3, mountains, no voids: the common 1-degree tile
# Usage: bench/build_bench.sh [TERRABOUND]   (default: build-release/terrabound, else build/)
# Env:   DATA=dir of the DEMs (default ../shared/data), OUT=scratch dir (default a mktemp),
#        THREADS="1 2", EXTRA="--max-zoom 12" to limit the pyramid (reported in 'zooms').
# Use a Release build: Debug is several times slower and keeps asserts on.
set -euo pipefail
cd "$(dirname "$0")/.."
TB=${1:-}
if [[ -z "$TB" ]]; then
    for c in build-release/terrabound build/terrabound; do
        [[ -x "$c" ]] && TB=$c && break
    done
fi
[[ -x "${TB:-}" ]] || { echo "build_bench.sh: no terrabound binary; pass its path" >&2; exit 2; }
[[ -x /usr/bin/time ]] || { echo "build_bench.sh: needs /usr/bin/time (apt-get install time)" >&2; exit 2; }
DATA=${DATA:-../shared/data}
THREADS=${THREADS:-"1 2"}
EXTRA=${EXTRA:-}
SCRATCH=${OUT:-$(mktemp -d)}
mkdir -p "$SCRATCH"
trap '[[ -z "${OUT:-}" ]] && rm -rf "$SCRATCH"' EXIT

printf 'input\tthreads\tzooms\ttiles\twall_s\ttiles_per_s\tpeak_rss_mb\tout_bytes\n'
for input in N48W125.hgt.zip N44W072.hgt; do
    dem=$DATA/$input
    if [[ ! -f "$dem" ]]; then
        echo "build_bench.sh: skipped $input: $dem is missing" >&2
        continue
    fi
    for t in $THREADS; do
        out=$SCRATCH/$input-$t
        rm -rf "$out"
        # shellcheck disable=SC2086
        /usr/bin/time -v -o "$SCRATCH/time.txt" "$TB" build "$dem" -o "$out" --threads "$t" \
            --layer terrain --formats glb --json $EXTRA >"$SCRATCH/summary.json" 2>"$SCRATCH/log.txt" || {
            echo "build_bench.sh: build of $input failed:" >&2
            tail -5 "$SCRATCH/log.txt" >&2
            exit 1
        }
        tiles=$(sed -n 's/.*"written":\([0-9]*\).*/\1/p' "$SCRATCH/summary.json")
        wall=$(sed -n 's/.*"seconds":\([0-9.e+-]*\).*/\1/p' "$SCRATCH/summary.json")
        rss=$(sed -n 's/.*Maximum resident set size (kbytes): //p' "$SCRATCH/time.txt")
        zooms=$(sed -n 's/.*tiles, zoom \([0-9.]*\),.*/\1/p' "$SCRATCH/log.txt" | head -1)
        bytes=$(du -sb "$out" | cut -f1)
        awk -v i="$input" -v t="$t" -v z="$zooms" -v n="$tiles" -v w="$wall" -v r="$rss" \
            -v b="$bytes" 'BEGIN { printf "%s\t%s\t%s\t%d\t%.2f\t%.1f\t%.1f\t%d\n",
                                   i, t, z, n, w, (w > 0 ? n / w : 0), r / 1024, b }'
        rm -rf "$out"
    done
done
