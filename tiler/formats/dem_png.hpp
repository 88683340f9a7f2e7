#pragma once
// Raster DEM tiles as PNG: heights packed into the red, green and blue bytes of each pixel, the
// two encodings web map clients decode (MapLibre GL raster-dem sources, deck.gl TerrainLayer):
//   terrarium: h = R * 256 + G + B / 256 - 32768            step 1/256 m, -32768 .. 32768 m
//   mapbox:    h = -10000 + (R * 65536 + G * 256 + B) * 0.1  step 0.1 m, -10000 .. 1667721.5 m
// zlib is the only dependency: the PNG is written here (8-bit truecolour, no alpha).
#include "tiler/formats/format.hpp"

#include <array>
#include <cstdint>
#include <span>
#include <string>

namespace tb::tiler {

// The 24-bit code of height `h` (metres) in `format` (Terrarium or Mapbox): the nearest step,
// clamped to the encoding's range, so decoding it is off by at most half a step inside it.
// Requires a finite h.
std::uint32_t encode_height(double h, Format format);
// The height a client decodes from code `code` (R << 16 | G << 8 | B).
double decode_height(std::uint32_t code, Format format);
// The encoding's step, metres: 1/256 (terrarium) or 0.1 (mapbox).
double height_step(Format format);

// A `width` x `height` PNG (8-bit RGB, row 0 at the top) of `heights` (row-major, finite,
// metres) encoded as `format`. Each row takes the PNG filter that makes it smallest by the
// usual minimum-sum-of-absolute-differences rule; zlib level 6. Deterministic. Requires
// 1 <= width, height <= 65535 and heights.size() == width * height.
std::string encode_dem_png(std::span<const double> heights, int width, int height, Format format);

} // namespace tb::tiler
