#!/bin/bash
# Mesher benchmark against delatin (Garland-Heckbert greedy insertion, the peer that honours
# eps), run in the same session on the same heightmaps. Not a test.
#
#   bench/mesh_bench.sh [--reps N] [--quick]
#
# Builds bench/mesh_bench in Release into build-bench (-DTB_BUILD_BENCH=ON), copies
# ../shared/bench (read-only) to bench/runs/peer (git-ignored), installs delatin there with
# npm, prepares the heightmaps with its tools, then for every case prints one TSV line:
#   input size eps ms triangles achieved_max_err peer_triangles ratio peer_ms speed_ratio linf_check
# ratio = our triangles / delatin's; speed_ratio = our samples/s / delatin's (same grid, so
# delatin ms / our ms). linf_check is the shared independent checker's verdict on our mesh.
# Exits 1 if any of our meshes misses a sample by more than eps.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
shared=${TB_SHARED_BENCH:-$root/../shared/bench}
runs=$root/bench/runs
peer=$runs/peer
reps=3
quick=0
while [ $# -gt 0 ]; do
    case $1 in
        --reps) reps=$2; shift 2 ;;
        --quick) quick=1; shift ;;
        *) echo "usage: $0 [--reps N] [--quick]" >&2; exit 2 ;;
    esac
done

# ---- build (Release, our target only, 2 jobs) ----
mkdir -p "$runs"
bench=$root/build-bench/mesh_bench
if ! { cmake -S "$root" -B "$root/build-bench" -DCMAKE_BUILD_TYPE=Release -DTB_BUILD_BENCH=ON \
        -DTB_BUILD_TESTS=OFF > "$runs/build.log" 2>&1 &&
       cmake --build "$root/build-bench" --target mesh_bench -j2 >> "$runs/build.log" 2>&1; }; then
    # mesh_bench needs core only, but CMake links it to tb_tiler; when another module does not
    # configure or build right now, compile it from the core sources with Release flags instead.
    echo "mesh_bench.sh: CMake build failed (see $runs/build.log); building from core/ alone" >&2
    mkdir -p "$root/build-bench"
    g++ -O3 -DNDEBUG -std=c++20 -Wall -Wextra -Wshadow -Wpedantic -I"$root" \
        "$root"/core/*.cpp "$root/bench/mesh_bench.cpp" -o "$bench"
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

status=0
printf 'input\tsize\teps\tms\ttriangles\tachieved_max_err\tpeer_triangles\tratio\tpeer_ms\tspeed_ratio\tlinf_check\n'
for c in "${cases[@]}"; do
    read -r name size epss <<< "$c"
    ours=$("$bench" --reps "$reps" --json "$runs/meshes" "$name=data/$name.f32:$size:$size" "$epss") ||
        status=1
    theirs=$(node run_js_peer.mjs delatin "data/$name.f32" "$size" "$size" "$epss" "$runs/meshes" \
        --reps "$reps")
    while IFS=$'\t' read -r input sz eps ms tris err _ _; do
        [ "$input" = input ] && continue
        line=$(grep "\"eps\":$eps," <<< "$theirs" || true)
        ptris=$(sed 's/.*"triangles":\([0-9]*\).*/\1/' <<< "$line")
        pms=$(sed 's/.*"ms":\([0-9.]*\).*/\1/' <<< "$line")
        verdict=ok
        ./linf_check "data/$name.f32" "$size" "$size" "$runs/meshes/$name-eps$eps.json" \
            --eps "$eps" > /dev/null 2>&1 || { verdict=FAIL; status=1; }
        ratio=$(awk -v a="$tris" -v b="$ptris" 'BEGIN { printf "%.3f", a / b }')
        speed=$(awk -v a="$ms" -v b="$pms" 'BEGIN { printf "%.2f", b / a }')
        printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$input" "$sz" "$eps" "$ms" "$tris" \
            "$err" "$ptris" "$ratio" "$pms" "$speed" "$verdict"
    done <<< "$ours"
done
exit $status
