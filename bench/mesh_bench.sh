#!/bin/bash
# Mesher benchmark against the greedy-insertion peers that honour eps, run in the same session
# on the same heightmaps: delatin (npm) always, and hmm (fogleman/hmm, C++) when HMM names its
# binary. Every effort level of ours (core::Effort) in the same run. Not a test.
#
#   [HMM=/path/to/hmm] bench/mesh_bench.sh [--reps N] [--quick] [--effort fast|balanced|best|all]
#                                          [--threads 1|2] [--no-check] [--svg FILE] [--instructions]
#                                          [--phases]
#
# Builds bench/mesh_bench with Release flags into build-bench (core/ alone), copies
# ../shared/bench (read-only) to bench/runs/peer (git-ignored), installs delatin there with
# npm, prepares the heightmaps with its tools, then for every case and level (--effort, default
# all: fast, balanced, best) prints one TSV line:
#   input size eps effort ms triangles achieved_max_err delatin_triangles delatin_ratio
#   delatin_ms delatin_speed hmm_triangles hmm_ratio hmm_ms hmm_speed linf_check
# *_ratio = our triangles / the peer's; *_speed = the peer's ms / our ms (same grid, so our
# samples/s over the peer's). ms is a best of N: every round runs our levels (one after the
# other, in one mesh_bench process) and then hmm at every eps, N rounds, so that all see the
# same load; delatin's N runs follow in one node process (its JIT warms up in-process).
# hmm reads a lossless 16-bit PNG of the same heights (../shared/bench/to_png16.mjs), its -e
# is eps in its own unit (see below), and its time is the "triangulating" time it prints.
# Without HMM the hmm columns are "-". linf_check is the shared independent checker's verdict
# on our mesh. The table is also written to bench/runs/mesh_bench.tsv. Exits 1 if any of our
# meshes misses a sample by more than eps.
# --threads is core's TriangulateOptions::threads (default 2, core's default): on these grids
# (2^18 samples and more) the mesher splits its fits, first scan, merge passes and final check
# in two halves, on two threads with 2 and one after the other with 1 (the same meshes).
# --instructions always counts with 1 (callgrind would not count the second thread's work).
# --no-check times our mesher without its final exact error pass (TriangulateOptions::
# check_error off), as the tiler runs it: hmm has no such pass. Every mesh is still measured
# after the timing, by mesh_bench's own exact pass and by linf_check.
# --svg FILE then draws triangles against time per case (bench/mesh_curve.mjs): our levels as
# a curve, hmm and delatin as marks, both axes as ratios to hmm (to delatin without HMM).
# --instructions then counts, under valgrind's callgrind, the instructions each mesher executes
# for every case (ours: core::triangulate, at each level; hmm: Triangulator::Run, without the
# copy of its points and triangles that its "triangulating" time also holds, about 1 %) and
# prints
#   input size eps effort ir hmm_ir hmm_ir_ratio
# with hmm_ir_ratio = hmm's count / ours. Unlike a time on a shared machine the counts repeat
# exactly, so they show small changes that the times bury in noise; they say nothing of cache
# misses or stalls, so the times stay the target. About 50x slower than a timing round.
# HMM_IR names another hmm binary for the count (default HMM): valgrind cannot run a
# -march=native build that uses AVX-512, so count a copy built without -march=native.
# --phases then runs ours N more times per case and level and prints where the fastest run's
# time went (mesh_bench --phases: core's TriangulatePhases), against hmm's time from the
# rounds above:
#   input size eps effort phases_ms anchors_ms start_ms first_scan_ms split_ms resplit_ms
#   renumber_ms merge_ms finish_ms split_triangles split_ratio to_split_speed merge_of_hmm
# phases_ms is the sum of the phases; split_ms the split agent's first round, resplit_ms its
# rounds after the merge passes. split_ratio = our triangles when the first round ends (before
# any merge) / hmm's; to_split_speed = hmm's ms / ours up to then (anchors + start + first
# scan + split); merge_of_hmm = the merge agent's ms / hmm's whole ms.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
shared=${TB_SHARED_BENCH:-$root/../shared/bench}
runs=$root/bench/runs
peer=$runs/peer
reps=3
quick=0
instructions=0
phases=0
effort=all
threads=2
check=()
svg=
while [ $# -gt 0 ]; do
    case $1 in
        --reps) reps=$2; shift 2 ;;
        --quick) quick=1; shift ;;
        --effort) effort=$2; shift 2 ;;
        --threads) threads=$2; shift 2 ;;
        --no-check) check=(--no-check); shift ;;
        --svg) svg=$2; shift 2 ;;
        --instructions) instructions=1; shift ;;
        --phases) phases=1; shift ;;
        *) echo "usage: [HMM=/path/to/hmm] $0 [--reps N] [--quick]" \
               "[--effort fast|balanced|best|all] [--threads 1|2] [--no-check] [--svg FILE]" \
               "[--instructions] [--phases]" >&2
           exit 2 ;;
    esac
done
case $effort in
    all) levels=(fast balanced best) ;;
    fast|balanced|best) levels=("$effort") ;;
    *) echo "mesh_bench.sh: --effort $effort: expected fast, balanced, best or all" >&2; exit 2 ;;
esac
[ -z "$svg" ] || svg=$(realpath -m "$svg")
if [ "$instructions" = 1 ] && ! command -v valgrind > /dev/null; then
    echo "mesh_bench.sh: --instructions needs valgrind (apt-get install valgrind)" >&2
    exit 2
fi

# ---- build: Release flags (CMake's -O3 -DNDEBUG), core/ and the bench alone ----
# mesh_bench needs core/ only. CMake's target links it to tb_tiler too, which would compile the
# whole tiler (GDAL, Draco) first and fail whenever another module does not build: compile the
# core sources and the bench directly, with the flags CMake's Release build gives them, and only
# when a source is newer than the binary.
mkdir -p "$runs" "$root/build-bench"
bench=$root/build-bench/mesh_bench
if [ ! -x "$bench" ] ||
    [ -n "$(find "$root/core" "$root/bench/mesh_bench.cpp" -newer "$bench" -print -quit)" ]; then
    g++ -O3 -DNDEBUG -std=c++20 -Wall -Wextra -Wshadow -Wpedantic -I"$root" \
        "$root"/core/*.cpp "$root/bench/mesh_bench.cpp" -o "$bench" -pthread \
        > "$runs/build.log" 2>&1 || { cat "$runs/build.log" >&2; exit 2; }
fi

# ---- peer tools: a writable copy of shared/bench with delatin installed ----
mkdir -p "$peer/data" "$runs/meshes"
for f in "$shared"/*.mjs "$shared"/*.sh "$shared"/*.cpp "$shared"/package*.json; do
    cp -u "$f" "$peer/"
done
if [ ! -d "$peer/node_modules/delatin" ]; then
    (cd "$peer" && npm install --no-audit --no-fund >/dev/null)
fi
[ -x "$peer/linf_check" ] || g++ -O2 -std=c++17 -o "$peer/linf_check" "$peer/linf_check.cpp"

# ---- heightmaps (why each is here) ----
data=$root/../shared/data
cd "$peer"
# synthetic, seeded: smooth relief plus 0.1 m steps; the README's reference synthetic map
[ -f data/synth-1025.f32 ] || node gen_synth.mjs data/synth-1025.f32 1025 1025 1 >/dev/null
# rugged real terrain (Andes, S33W071): the issue's reference case
[ -f data/andes-1025.f32 ] || ./prep_dem.sh "$data/S33W071.tif" andes-1025 88 88 1025 >/dev/null
# moderate real terrain (White Mountains, N44W072): mixes flat valleys and steep slopes
[ -f data/whitemtn-1025.f32 ] || ./prep_dem.sh "$data/N44W072.hgt" whitemtn-1025 88 88 1025 >/dev/null
# a single smooth cone in float heights (Fuji, martini's fixture), padded to 513
[ -f data/fuji-513.f32 ] || ./prep_dem.sh "$data/fuji_float32.tif" fuji-513 0 0 513 1 >/dev/null

if [ "$quick" = 1 ]; then
    cases=("andes-1025 1025 40" "fuji-513 513 6")
else
    cases=("synth-1025 1025 10,1.25" "andes-1025 1025 160,40,15" "whitemtn-1025 1025 40,5"
           "fuji-513 513 50,6")
fi

# ---- hmm (optional): HMM names a binary built from fogleman/hmm outside this repository ----
hmm=${HMM:-}
if [ -n "$hmm" ] && [ ! -x "$hmm" ]; then
    echo "mesh_bench.sh: HMM=$hmm is not an executable" >&2
    exit 2
fi
[ -n "$hmm" ] || echo "mesh_bench.sh: HMM not set, skipping hmm (HMM=/path/to/hmm $0 to run it)" >&2

# min of two numbers, the first may be empty
minimum() { awk -v a="$1" -v b="$2" 'BEGIN { print (a == "" || b + 0 < a + 0) ? b : a }'; }

status=0
declare -A hmm_unit=() hmm_lossy=() # per input, for --instructions
declare -A hmm_ms=() hmm_tris=()    # per "input eps", for --phases
table=$runs/mesh_bench.tsv
{
printf 'input\tsize\teps\teffort\tms\ttriangles\tachieved_max_err\tdelatin_triangles'
printf '\tdelatin_ratio\tdelatin_ms\tdelatin_speed\thmm_triangles\thmm_ratio\thmm_ms\thmm_speed'
printf '\tlinf_check\n'
} | tee "$table"
for c in "${cases[@]}"; do
    read -r name size epss <<< "$c"
    if [ -n "$hmm" ]; then
        # hmm reads a 16-bit PNG and divides its values by 65535: with to_png16's quantum q
        # (k = (h - min) / q, exact here) one hmm height unit is unit = q * 65535 of ours, so
        # eps of ours is eps / unit of hmm's (-e; -z only scales its output). A lossy PNG moves
        # heights by up to max_quant_error: eps is tightened by that much.
        png=$runs/meshes/$name.png
        q=$(node to_png16.mjs "data/$name.f32" "$size" "$size" "$png")
        unit=$(sed 's/.*"unit":\([0-9.e+-]*\).*/\1/' <<< "$q")
        lossy=$(sed 's/.*"max_quant_error":\([0-9.e+-]*\).*/\1/' <<< "$q")
        grep -q '"lossless":true' <<< "$q" && lossy=0 ||
            echo "mesh_bench.sh: $name is not exact in 16 bits (max rounding $lossy)" >&2
        hmm_unit[$name]=$unit
        hmm_lossy[$name]=$lossy
    fi
    declare -A ms=() hms=() htris=()
    ours=""
    # Rounds: our levels (alternated inside mesh_bench) then hmm at every eps, so that all see
    # the same load; best of the rounds.
    for ((r = 0; r < reps; ++r)); do
        for eps in ${epss//,/ }; do
            json=()
            [ "$r" = 0 ] && json=(--json "$runs/meshes")
            lines=$("$bench" --reps 1 --effort "$effort" --threads "$threads" "${check[@]}" "${json[@]}" \
                "$name=data/$name.f32:$size:$size" "$eps" | tail -n +2) || status=1
            [ "$r" = 0 ] && ours+="$lines"$'\n'
            while IFS=$'\t' read -r _ _ _ t _ _ _ _ level; do
                ms[$eps $level]=$(minimum "${ms[$eps $level]:-}" "$t")
            done <<< "$lines"
            if [ -n "$hmm" ]; then
                e=$(awk -v e="$eps" -v l="$lossy" -v u="$unit" 'BEGIN { printf "%.9g", (e - l) / u }')
                out=$("$hmm" "$png" "$runs/meshes/hmm-$name-eps$eps.stl" -z 65535 -e "$e")
                t=$(sed -n 's/^triangulating\.\.\. \([0-9.e+-]*\)s$/\1/p' <<< "$out")
                hms[$eps]=$(minimum "${hms[$eps]:-}" "$(awk -v t="$t" 'BEGIN { printf "%.1f", t * 1000 }')")
                htris[$eps]=$(sed -n 's/^  triangles = \([0-9]*\)$/\1/p' <<< "$out")
            fi
        done
    done
    theirs=$(node run_js_peer.mjs delatin "data/$name.f32" "$size" "$size" "$epss" "$runs/meshes" \
        --reps "$reps")
    while IFS=$'\t' read -r input sz eps _ tris err _ _ level; do
        [ -z "$input" ] && continue
        line=$(grep "\"eps\":$eps," <<< "$theirs" || true)
        ptris=$(sed 's/.*"triangles":\([0-9]*\).*/\1/' <<< "$line")
        pms=$(sed 's/.*"ms":\([0-9.]*\).*/\1/' <<< "$line")
        verdict=ok
        ./linf_check "data/$name.f32" "$size" "$size" "$runs/meshes/$name-eps$eps-$level.json" \
            --eps "$eps" > /dev/null 2>&1 || { verdict=FAIL; status=1; }
        t=${ms[$eps $level]}
        ratio=$(awk -v a="$tris" -v b="$ptris" 'BEGIN { printf "%.3f", a / b }')
        speed=$(awk -v a="$t" -v b="$pms" 'BEGIN { printf "%.2f", b / a }')
        hcols="-\t-\t-\t-"
        if [ -n "$hmm" ]; then
            hcols=$(awk -v a="$tris" -v b="${htris[$eps]}" -v t="$t" -v h="${hms[$eps]}" \
                'BEGIN { printf "%d\t%.3f\t%s\t%.2f", b, a / b, h, h / t }')
            hmm_ms["$name $eps"]=${hms[$eps]}
            hmm_tris["$name $eps"]=${htris[$eps]}
        fi
        printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%b\t%s\n' "$input" "$sz" "$eps" \
            "$level" "$t" "$tris" "$err" "$ptris" "$ratio" "$pms" "$speed" "$hcols" "$verdict" |
            tee -a "$table"
    done <<< "$ours"
    unset ms hms htris
done

# ---- the curve (--svg): triangles against time per case, levels joined, peers marked ----
if [ -n "$svg" ]; then
    mkdir -p "$(dirname "$svg")"
    node "$root/bench/mesh_curve.mjs" < "$table" > "$svg"
    echo "mesh_bench.sh: wrote $svg" >&2
fi

# ---- instruction counts (--instructions): one run of each mesher per case under callgrind ----
# Prints the count callgrind collected inside the named function(s) of one run.
count_ir() {
    local function=$1
    shift
    valgrind --tool=callgrind --callgrind-out-file=/dev/null --toggle-collect="$function" "$@" \
        2>&1 > /dev/null | sed -n 's/.*Collected : \([0-9]*\)$/\1/p'
}
if [ "$instructions" = 1 ]; then
    hmm_ir=${HMM_IR:-$hmm}
    printf 'input\tsize\teps\teffort\tir\thmm_ir\thmm_ir_ratio\n'
    for c in "${cases[@]}"; do
        read -r name size epss <<< "$c"
        for eps in ${epss//,/ }; do
            hir=
            if [ -n "$hmm" ]; then
                # The PNG and eps of the timing rounds above.
                e=$(awk -v e="$eps" -v l="${hmm_lossy[$name]}" -v u="${hmm_unit[$name]}" \
                    'BEGIN { printf "%.9g", (e - l) / u }')
                hir=$(count_ir 'Triangulator::Run*' "$hmm_ir" "$runs/meshes/$name.png" \
                    "$runs/meshes/hmm-$name-eps$eps.stl" -z 65535 -e "$e" || true)
                if [ -z "$hir" ] || [ "$hir" = 0 ]; then
                    # valgrind stops at instructions it does not know (AVX-512 in a
                    # -march=native build on a CPU that has it): say so, count ours anyway.
                    echo "mesh_bench.sh: hmm ($hmm_ir) did not run under valgrind; build a" \
                        "copy without -march=native and pass it in HMM_IR" >&2
                    hir=
                fi
            fi
            for level in "${levels[@]}"; do
                ir=$(count_ir 'tb::core::triangulate(*' "$bench" --reps 1 --threads 1 \
                    --effort "$level" "$name=data/$name.f32:$size:$size" "$eps")
                hcols="-\t-"
                if [ -n "$hir" ]; then
                    hcols=$(awk -v a="$ir" -v b="$hir" 'BEGIN { printf "%.0f\t%.3f", b, b / a }')
                fi
                printf '%s\t%s\t%s\t%s\t%s\t%b\n' "$name" "$size" "$eps" "$level" "$ir" "$hcols"
            done
        done
    done
fi

# ---- phases (--phases): where our time goes, against hmm's whole run ----
if [ "$phases" = 1 ]; then
    printf 'input\tsize\teps\teffort\tphases_ms\tanchors_ms\tstart_ms\tfirst_scan_ms\tsplit_ms'
    printf '\tresplit_ms\trenumber_ms\tmerge_ms\tfinish_ms\tsplit_triangles\tsplit_ratio'
    printf '\tto_split_speed\tmerge_of_hmm\n'
    for c in "${cases[@]}"; do
        read -r name size epss <<< "$c"
        "$bench" --phases --reps "$reps" --effort "$effort" --threads "$threads" "${check[@]}" \
            "$name=data/$name.f32:$size:$size" \
            "$epss" | tail -n +2 |
            while IFS=$'\t' read -r _ sz eps ms _ an st fs sp rs rn mg fin _ stris _ _ level; do
                h=${hmm_ms["$name $eps"]:-}
                ht=${hmm_tris["$name $eps"]:-}
                hcols="-\t-\t-"
                if [ -n "$h" ]; then
                    hcols=$(awk -v tris="$stris" -v ht="$ht" -v h="$h" -v mg="$mg" -v an="$an" \
                        -v st="$st" -v fs="$fs" -v sp="$sp" 'BEGIN { u = an + st + fs + sp
                        printf "%.3f\t%.2f\t%.2f", tris / ht, h / u, mg / h }')
                fi
                printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%b\n' "$name" \
                    "$sz" "$eps" "$level" "$ms" "$an" "$st" "$fs" "$sp" "$rs" "$rn" "$mg" "$fin" \
                    "$stris" "$hcols"
            done
    done
fi
exit $status
