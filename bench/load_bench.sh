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
#   THREADS (generation threads, default 0: one per core), QUEUE_LIMIT (default 64),
#   MIN_ZOOM, MAX_ZOOM (default 8, 12), EPS_LEVELS (default "2, 4, 8"; empty: none),
#   DISTINCT (cold tiles asked: a seeded sample of that many; default 0: every tile), SEED (1),
#   RETRY_AFTER (1: a client waits a 503's Retry-After before asking again; default 0: at once),
#   and the server settings MEMORY_MB, CACHE_MB, START_WAIT_MS, DEADLINE_MS (unset: the
#   server's defaults; an older binary rejects a key it does not know).
# Bounded: DURATION seconds of load, at most MAX_REQUESTS requests, each tile asked until it is
# answered 200 (a 503 puts it back at the end of the list).
#
# The issue-37 case (100 connections over 1,000 distinct uncached tiles for 60 s):
#   CONCURRENCY=100 DURATION=60 IDLE=0 SLOW=0 DISTINCT=1000 RETRY_AFTER=1 MIN_ZOOM=11 \
#   MAX_ZOOM=14 EPS_LEVELS= MEMORY_MB=512 bench/load_bench.sh bench/runs/lod/N48W125-x4.tif
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

# By default zooms 8..12 (max_zoom 12 as in http_bench.sh) and three eps levels: a few thousand
# distinct cold tiles, more than the run can generate, so generation stays saturated.
optional=
for pair in memory_mb:MEMORY_MB cache_mb:CACHE_MB start_wait_ms:START_WAIT_MS \
            deadline_ms:DEADLINE_MS; do
    key=${pair%%:*} var=${pair#*:}
    if [ -n "${!var:-}" ]; then optional="$optional, \"$key\": ${!var}"; fi
done
cat >"$WORK/load.json" <<JSON
{"server": {"host": "127.0.0.1", "port": 0, "threads": ${THREADS:-0}, "log_level": "warn",
            "queue_limit": ${QUEUE_LIMIT:-64}$optional},
 "layers": [{"name": "load", "sources": ["$DEM"], "max_zoom": ${MAX_ZOOM:-12},
             "min_zoom": ${MIN_ZOOM:-8}, "eps_levels": [${EPS_LEVELS-2, 4, 8}], "formats": ["glb"]}]}
JSON
log "config: $(tr -s ' \n' ' ' <"$WORK/load.json")"
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
