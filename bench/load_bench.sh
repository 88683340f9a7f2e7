#!/usr/bin/env bash
# Overload benchmark of `terrabound serve` on loopback: cold tile generation saturated by
# CONCURRENCY clients while IDLE idle and SLOW slow-header connections are held open; reports
# req/s, status mix and p50/p99 of the load, /health and cached-tile latency during it, and the
# server's RSS over time (bench/load_bench.mjs prints the TSV).
#
#   bench/load_bench.sh [DEM]      (default: ../shared/data/N44W072.hgt, else data/N57E011.hgt)
#
# Environment: TB_BIN (default: a Release build in build-bench/), DURATION (s, default 20),
#   CONCURRENCY (default 128), IDLE (default 1000), SLOW (default 100), MAX_REQUESTS (200000),
#   THREADS (generation threads, default 0: one per core), QUEUE_LIMIT (default 64).
# Bounded: DURATION seconds of load, at most MAX_REQUESTS requests, each tile asked once.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)

log() { printf '%s load_bench: %s\n' "$(date -u +%FT%TZ)" "$*" >&2; }
die() { log "$*"; exit 1; }

DEM=${1:-}
if [ -z "$DEM" ]; then
    for candidate in "$ROOT/../shared/data/N44W072.hgt" "$ROOT/data/N57E011.hgt"; do
        if [ -f "$candidate" ]; then DEM=$candidate; break; fi
    done
fi
[ -n "$DEM" ] && [ -f "$DEM" ] || die "no DEM; pass one (a 1201x1201 SRTM .hgt)"
DEM=$(realpath "$DEM")
if [ -z "${TB_BIN:-}" ]; then
    cmake -S "$ROOT" -B "$ROOT/build-bench" -DCMAKE_BUILD_TYPE=Release -DTB_BUILD_TESTS=OFF >/dev/null
    cmake --build "$ROOT/build-bench" --target terrabound -j2 >/dev/null
    TB_BIN=$ROOT/build-bench/terrabound
fi

WORK=$(mktemp -d /tmp/tb_load_bench.XXXXXX)
SERVER_PID=
cleanup() {
    if [ -n "$SERVER_PID" ]; then kill "$SERVER_PID" 2>/dev/null || true; wait "$SERVER_PID" 2>/dev/null || true; fi
    rm -rf "$WORK"
}
trap cleanup EXIT

# Zooms 8..12 (max_zoom 12 as in http_bench.sh) and three eps levels: a few thousand distinct
# cold tiles, more than the run can generate, so generation stays saturated.
cat >"$WORK/load.json" <<JSON
{"server": {"host": "127.0.0.1", "port": 0, "threads": ${THREADS:-0}, "log_level": "warn",
            "queue_limit": ${QUEUE_LIMIT:-64}},
 "layers": [{"name": "load", "sources": ["$DEM"], "max_zoom": 12, "min_zoom": 8,
             "eps_levels": [2, 4, 8], "formats": ["glb"]}]}
JSON
# log_level warn (one line per request would slow the run), so the port is chosen here and the
# server is up once /health answers.
PORT=$(node -e 'const s=require("net").createServer().listen(0,"127.0.0.1",()=>{console.log(s.address().port);s.close()})')
"$TB_BIN" serve "$WORK/load.json" --web none --port "$PORT" 2>"$WORK/serve.log" &
SERVER_PID=$!
up=
for _ in $(seq 1 600); do
    if curl -fs "http://127.0.0.1:$PORT/health" >/dev/null 2>&1; then up=1; break; fi
    kill -0 "$SERVER_PID" 2>/dev/null || die "terrabound serve exited: $(cat "$WORK/serve.log")"
    sleep 0.1
done
[ -n "$up" ] || die "terrabound serve did not start: $(cat "$WORK/serve.log")"
log "serving $DEM on port $PORT (pid $SERVER_PID)"
PORT=$PORT PID=$SERVER_PID node "$ROOT/bench/load_bench.mjs"
