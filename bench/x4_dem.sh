#!/usr/bin/env bash
# Makes the 207 Mpixel DEM of the level-of-detail benches once, at DEM (argument):
# N48W125.hgt (from $DATA, default /work/shared/data) resampled 400 % cubic to 14404^2 Int16,
# tiled and deflated, nodata -32768 kept. Does nothing if DEM exists. Needs gdal_translate, unzip.
set -euo pipefail
DEM=$1
DATA=${DATA:-/work/shared/data}
[[ -s $DEM ]] && exit 0
mkdir -p "$(dirname "$DEM")"
cd "$(dirname "$DEM")"
unzip -o -q "$DATA/N48W125.hgt.zip" N48W125.hgt
gdal_translate -q -outsize 400% 400% -r cubic -ot Int16 -co TILED=YES -co COMPRESS=DEFLATE \
    N48W125.hgt "$(basename "$DEM").part.tif"
mv "$(basename "$DEM").part.tif" "$(basename "$DEM")"
