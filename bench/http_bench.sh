#!/usr/bin/env bash
# HTTP benchmark of `terrabound serve`, against nginx serving the same tiles in the same run.
#
#   bench/http_bench.sh [DEM]        (default: ../shared/data/N44W072.hgt, else data/N57E011.hgt)
#
# Environment: TB_BIN (terrabound binary; default: build a Release one in build-bench/),
#              DURATION (wrk seconds per run, default 10), ROUNDS (alternated runs per server,
#              default 3), CONNECTIONS (default 64),
#              COLD_PER_ZOOM (cold tiles timed per zoom, default 20), EFFORT (the layer's
#              mesher effort: fast, balanced or best; default the layer's default),
#              HOT (0: the cold cases only, which are the ones EFFORT changes; default 1).
#
# Cases (one TSV line each, on stdout; logs on stderr):
#   hot_terrabound / hot_nginx: requests/s and p50/p99 latency (ms) of wrk over the same set of
#     cached tiles: terrabound from its memory LRU, nginx from the directory store terrabound
#     wrote. The figure is the ratio terrabound/nginx requests/s (target >= 0.9, with
#     terrabound's p99 under 10 ms, in the same run).
#   cold_zZ: on-demand latency of tiles never requested before (fresh server, no store) at
#     zooms 8..12 of a 1201x1201 SRTM tile (target p50 < 20 ms, p99 < 50 ms), one keep-alive
#     connection.
# Needs wrk, nginx and curl (Debian: apt-get install -y wrk nginx-light curl); HOT=0 needs curl only.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)

log() { printf '%s http_bench: %s\n' "$(date -u +%FT%TZ)" "$*" >&2; }
die() { log "$*"; exit 1; }

TOOLS="curl python3"
[ "${HOT:-1}" = 0 ] || TOOLS="wrk nginx $TOOLS"
for tool in $TOOLS; do
    command -v "$tool" >/dev/null || die "$tool is missing; apt-get install -y wrk nginx-light curl"
done

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
DURATION=${DURATION:-10}
CONNECTIONS=${CONNECTIONS:-64}
COLD_PER_ZOOM=${COLD_PER_ZOOM:-20}
ROUNDS=${ROUNDS:-3}

WORK=$(mktemp -d /tmp/tb_http_bench.XXXXXX)
PIDS=()
cleanup() {
    for pid in "${PIDS[@]}"; do kill "$pid" 2>/dev/null || true; done
    wait 2>/dev/null || true
    rm -rf "$WORK"
}
trap cleanup EXIT

free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }

# Starts terrabound serve with config $1, logging to $2; sets PORT and SERVER_PID.
start_server() {
    local config=$1 logfile=$2
    PORT=$(free_port)
    "$TB_BIN" serve "$config" --port "$PORT" 2>"$logfile" &
    SERVER_PID=$!
    PIDS+=("$SERVER_PID")
    for _ in $(seq 1 200); do
        curl -fs "http://127.0.0.1:$PORT/health" >/dev/null 2>&1 && return 0
        kill -0 "$SERVER_PID" 2>/dev/null || { cat "$logfile" >&2; die "terrabound exited"; }
        sleep 0.05
    done
    die "terrabound did not start"
}

stop_server() {
    kill -TERM "$SERVER_PID"
    wait "$SERVER_PID" || true
}

write_config() {  # $1 = file, $2 = store (JSON value)
    cat >"$1" <<EOF
{"server": {"threads": 2, "cache_mb": 512, "log_level": "warn", "queue_limit": 1000},
 "layers": [{"name": "bench", "sources": ["$DEM"], "min_zoom": 8, "max_zoom": 12,
             "formats": ["glb"], "store": $2${EFFORT:+, \"effort\": \"$EFFORT\"}}]}
EOF
}

# Tile URLs (paths) of zoom $1 that hold data, from /layers' bounds, shuffled with a seed.
tile_paths() {
    local z=$1 count=$2
    curl -fs "http://127.0.0.1:$PORT/layers" | python3 -c '
import json, math, random, sys
z, count = int(sys.argv[1]), int(sys.argv[2])
layer = json.load(sys.stdin)["layers"][0]
b = layer["bounds"]
size = 180.0 / 2**z   # geodetic: 2 x 1 tiles at z = 0, y from the south
eps = 1e-9
x0, x1 = math.floor((b["west"] + 180) / size + eps), math.ceil((b["east"] + 180) / size - eps) - 1
y0, y1 = math.floor((b["south"] + 90) / size + eps), math.ceil((b["north"] + 90) / size - eps) - 1
tiles = [(x, y) for x in range(x0, x1 + 1) for y in range(y0, y1 + 1)]
random.Random(z).shuffle(tiles)
for x, y in tiles[:count]:
    print(f"/bench/{z}/{x}/{y}.glb")
' "$z" "$count"
}

percentiles() {  # stdin: seconds, one per line -> "p50_ms p99_ms n"
    python3 -c '
import sys
v = sorted(float(l) * 1000 for l in sys.stdin if l.strip())
def q(p): return v[min(len(v) - 1, int(round(p * (len(v) - 1))))]
print(f"{q(0.5):.2f}\t{q(0.99):.2f}\t{len(v)}")'
}

printf 'case\trequests_per_s\tp50_ms\tp99_ms\tn\tnote\n'

# ---- cold: fresh server, no store, every tile requested for the first time ----
write_config "$WORK/cold.json" null
start_server "$WORK/cold.json" "$WORK/cold.log"
for z in 8 9 10 11 12; do
    tile_paths "$z" "$COLD_PER_ZOOM" | sed "s|^|http://127.0.0.1:$PORT|" >"$WORK/cold_$z.txt"
    # One curl, one keep-alive connection, one tile after another: latency = generation.
    sed 's|.*|url = "&"\noutput = "/dev/null"|' "$WORK/cold_$z.txt" >"$WORK/cold_$z.curl"
    curl -s -w '%{http_code} %{time_total}\n' -K "$WORK/cold_$z.curl" >"$WORK/cold_$z.out"
    grep -vq '^200 ' "$WORK/cold_$z.out" && die "a cold tile failed: $(grep -v '^200 ' "$WORK/cold_$z.out" | head -1)"
    stats=$(cut -d' ' -f2 "$WORK/cold_$z.out" | percentiles)
    # Mean time inside make_tile (mesh + encode) for this zoom, from the server's counters.
    curl -fs "http://127.0.0.1:$PORT/metrics" >"$WORK/metrics_$z.txt"
    gen=$(python3 -c '
import sys
def value(path, name):
    try:
        for line in open(path):
            if line.startswith(name + " "):
                return float(line.split()[1])
    except FileNotFoundError:
        pass
    return 0.0
now, before = sys.argv[1], sys.argv[2]
n = value(now, "tb_tiles_generated_total") - value(before, "tb_tiles_generated_total")
t = value(now, "tb_tile_generation_seconds_total") - value(before, "tb_tile_generation_seconds_total")
print(f"{t / n * 1000:.1f}" if n else "-")' "$WORK/metrics_$z.txt" "$WORK/metrics_prev.txt")
    cp "$WORK/metrics_$z.txt" "$WORK/metrics_prev.txt"
    printf 'cold_z%s\t-\t%s\tfresh tiles, sequential; mean make_tile %s ms\n' "$z" "$stats" "$gen"
done
stop_server

[ "${HOT:-1}" = 0 ] && exit 0

# ---- hot: the same tiles from terrabound's LRU and from nginx over the directory store ----
write_config "$WORK/hot.json" "\"$WORK/store\""
start_server "$WORK/hot.json" "$WORK/hot.log"
: >"$WORK/hot_paths.txt"
for z in 10 11; do tile_paths "$z" 100 >>"$WORK/hot_paths.txt"; done
sed "s|.*|url = \"http://127.0.0.1:$PORT&\"\noutput = \"/dev/null\"|" "$WORK/hot_paths.txt" \
    >"$WORK/warm.curl"
curl -fs -K "$WORK/warm.curl"  # warm up: generates every tile into the LRU and the store
N_HOT=$(wc -l <"$WORK/hot_paths.txt")
[ "$(find "$WORK/store" -name '*.glb' | wc -l)" -eq "$N_HOT" ] || die "the store misses tiles"

cat >"$WORK/paths.lua" <<EOF
local paths = {}
for line in io.lines("$WORK/hot_paths.txt") do paths[#paths + 1] = line end
local i = 0
request = function()
    i = i % #paths + 1
    return wrk.format("GET", paths[i])
end
EOF

wrk_run() {  # $1 = base URL -> "rps p50 p99"
    wrk -t2 -c"$CONNECTIONS" -d"${DURATION}s" --latency -s "$WORK/paths.lua" "$1" | python3 -c '
import re, sys
text = sys.stdin.read()
def ms(label):
    m = re.search(r"^\s*" + label + r"\s+([\d.]+)(us|ms|s)\s*$", text, re.M)
    v = float(m.group(1))
    return v / 1000 if m.group(2) == "us" else v * 1000 if m.group(2) == "s" else v
rps = float(re.search(r"Requests/sec:\s+([\d.]+)", text).group(1))
errors = re.search(r"Non-2xx or 3xx responses: (\d+)", text)
if errors: sys.exit("wrk: non-2xx responses: " + errors.group(1))
p50, p99 = ms("50%"), ms("99%")
print(f"{rps:.0f}\t{p50:.3f}\t{p99:.3f}")'
}


NGINX_PORT=$(free_port)
mkdir -p "$WORK/nginx"
cat >"$WORK/nginx/nginx.conf" <<EOF
worker_processes 2;
pid $WORK/nginx/nginx.pid;
error_log $WORK/nginx/error.log warn;
events { worker_connections 1024; }
http {
    access_log off;
    sendfile on;
    tcp_nopush on;
    keepalive_requests 100000;
    types { model/gltf-binary glb; application/json json; }
    client_body_temp_path $WORK/nginx/tmp;
    proxy_temp_path $WORK/nginx/tmp;
    fastcgi_temp_path $WORK/nginx/tmp;
    uwsgi_temp_path $WORK/nginx/tmp;
    scgi_temp_path $WORK/nginx/tmp;
    server {
        listen 127.0.0.1:$NGINX_PORT;
        root $WORK/store;
        etag on;
        add_header Access-Control-Allow-Origin *;
    }
}
EOF
mkdir -p "$WORK/nginx/tmp"
chmod -R a+rX "$WORK"
nginx -p "$WORK/nginx" -c "$WORK/nginx/nginx.conf" -g 'daemon off;' 2>"$WORK/nginx/stderr.log" &
PIDS+=($!)
for _ in $(seq 1 100); do
    curl -fs -o /dev/null "http://127.0.0.1:$NGINX_PORT$(head -1 "$WORK/hot_paths.txt")" && break
    sleep 0.05
done
# Alternate the two servers ROUNDS times (the machine is shared: load drifts) and report each
# one's median run; the ratio compares the medians.
: >"$WORK/hot_tb.tsv"
: >"$WORK/hot_nginx.tsv"
for _ in $(seq 1 "$ROUNDS"); do
    wrk_run "http://127.0.0.1:$PORT" >>"$WORK/hot_tb.tsv"
    wrk_run "http://127.0.0.1:$NGINX_PORT" >>"$WORK/hot_nginx.tsv"
done
median_run() { sort -n -k1,1 "$1" | sed -n "$(( ($(wc -l <"$1") + 1) / 2 ))p"; }
TB_HOT=$(median_run "$WORK/hot_tb.tsv")
NGINX_HOT=$(median_run "$WORK/hot_nginx.tsv")
stop_server
printf 'hot_terrabound\t%s\t%s\tmemory LRU, %s connections, median of %s runs\n' \
    "$TB_HOT" "$N_HOT" "$CONNECTIONS" "$ROUNDS"
printf 'hot_nginx\t%s\t%s\tsame files from the directory store, median of %s runs\n' \
    "$NGINX_HOT" "$N_HOT" "$ROUNDS"

python3 -c '
import sys
tb, ng = float(sys.argv[1]), float(sys.argv[2])
print(f"ratio_rps\t{tb / ng:.2f}\t-\t-\t-\tterrabound / nginx requests/s (target >= 0.9, "
      "terrabound p99 < 10 ms)")
' "$(cut -f1 <<<"$TB_HOT")" "$(cut -f1 <<<"$NGINX_HOT")"
