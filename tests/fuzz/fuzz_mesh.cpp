// libFuzzer harness: raster -> mesh -> encode -> decode. The input picks a small geodetic tile
// raster (size, zoom, position, heights, voids) and an eps; the harness meshes it as layers do
// (mesh_tile at tile_error_budget), encodes it as glb and drc, decodes both and checks the
// promise with the brute-force oracle of the tiler tests: every valid sample lies within eps
// of the decoded surface. Anything else than the documented refusals aborts.
//
// Input layout (missing bytes read as 0):
//   [0] tile size N = 2 + b % 31      [1] eps = 0.01 m * 2^(b % 14)
//   [2] zoom = 3 + b % 16             [3] [4] x, y: fractions of the zoom's columns and rows
//                                     (rows touching a pole excepted)
//   [5] height scale: 2^(b % 10) / 2048 m per unit, so heights stay within +-8192 m
//   [6..] heights: one signed 16-bit little-endian value per sample, repeated cyclically;
//         -32768 marks a void (valid = 0, height of the previous sample)
#include "core/error.hpp"
#include "core/triangulate.hpp"
#include "tests/tiler/linf_oracle.hpp"
#include "tiler/formats/draco_decode.hpp"
#include "tiler/formats/encode.hpp"
#include "tiler/geodesy.hpp"
#include "tiler/layer.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace {

using namespace tb;
using namespace tb::tiler;

[[noreturn]] void fail(const char* what, double value = 0) {
    std::fprintf(stderr, "fuzz_mesh: %s (%.17g)\n", what, value);
    std::abort();
}

struct Bytes {
    const std::uint8_t* data;
    std::size_t size;
    std::uint8_t at(std::size_t k) const { return k < size ? data[k] : 0; }
};

TileRaster raster_from(const Bytes& in) {
    TileRaster r;
    r.scheme = Scheme::Geodetic;
    r.size = 2 + in.at(0) % 31;
    const int z = 3 + in.at(2) % 16;
    r.id.z = z;
    r.id.x = static_cast<std::int64_t>(in.at(3) / 256.0 * tiles_across(Scheme::Geodetic, z));
    // Rows touching a pole are left out: their polar edge is a single point, where longitude
    // (and so the oracle's mapping back to tile columns) is undefined.
    const std::int64_t rows = tiles_down(Scheme::Geodetic, z);
    r.id.y = 1 + static_cast<std::int64_t>(in.at(4) / 256.0 * (rows - 2));
    r.bounds = tile_bounds(Scheme::Geodetic, r.id);
    const double unit = std::ldexp(1.0, in.at(5) % 10) / 2048;
    const int n = r.size + 1;
    r.grid.width = r.grid.height = n;
    const std::size_t count = static_cast<std::size_t>(n) * n;
    const std::size_t values = in.size > 6 ? (in.size - 6) / 2 : 0;
    // The smallest ground distance between neighbouring samples: east-west at the poleward edge.
    const double poleward = std::max(std::abs(r.bounds.south), std::abs(r.bounds.north));
    const double spacing = sample_spacing_m(Scheme::Geodetic, z, r.size) *
                           std::min(1.0, std::cos(poleward * 3.14159265358979323846 / 180));
    const double max_step = kQuantMaxSlope * spacing / 2;
    std::vector<std::uint8_t> valid(count, 1);
    bool any_void = false;
    float previous = 0;
    for (std::size_t k = 0; k < count; ++k) {
        std::int16_t raw = 0;
        if (values > 0) {
            const std::size_t at = 6 + 2 * (k % values);
            raw = static_cast<std::int16_t>(in.at(at) | (in.at(at + 1) << 8));
        }
        if (raw == INT16_MIN) {
            valid[k] = 0;
            any_void = true;
            r.grid.heights.push_back(previous);
            continue;
        }
        // Slopes up to kQuantMaxSlope, the steepest the error budget covers on tile borders
        // (steeper cliffs are checked by encode_tile itself): within that of the west and
        // north neighbours.
        double h = raw * unit;
        const std::size_t i = k % n, j = k / n;
        double lo = -INFINITY, hi = INFINITY;
        if (i > 0) {
            lo = std::max(lo, r.grid.heights[k - 1] - max_step);
            hi = std::min(hi, r.grid.heights[k - 1] + max_step);
        }
        if (j > 0) {
            lo = std::max(lo, r.grid.heights[k - n] - max_step);
            hi = std::min(hi, r.grid.heights[k - n] + max_step);
        }
        h = lo <= hi ? std::clamp(h, lo, hi) : (lo + hi) / 2;
        previous = static_cast<float>(h);
        r.grid.heights.push_back(previous);
    }
    if (any_void) {
        r.grid.valid = std::move(valid);
    }
    return r;
}

// Decoded positions -> tile grid coordinates (column, row, ellipsoidal height), by the
// documented sample layout of a geodetic TileRaster.
std::vector<test::OracleVertex> to_grid(const DecodedTile& d, Format f, const TileRaster& r) {
    std::vector<test::OracleVertex> out;
    EnuFrame frame{};
    if (f == Format::Drc) {
        frame = enu_frame({d.metadata.doubles.at("origin_lon_deg"),
                           d.metadata.doubles.at("origin_lat_deg"),
                           d.metadata.doubles.at("origin_h_m")});
    }
    for (const auto& p : d.positions) {
        Ecef e{};
        if (f == Format::Glb) {
            // glTF y-up (X, Y, Z) = ECEF (x, z, -y), relative to the root translation.
            e = {d.translation[0] + p[0], -(d.translation[2] + p[2]), d.translation[1] + p[1]};
        } else {
            e = enu_to_ecef(frame, p);
        }
        const Geodetic g = to_geodetic(e);
        // A vertex on the antimeridian may come back as +180 or -180.
        double lon = g.lon;
        if (lon - r.bounds.west > 180) {
            lon -= 360;
        } else if (lon - r.bounds.west < -180) {
            lon += 360;
        }
        out.push_back({(lon - r.bounds.west) / (r.bounds.east - r.bounds.west) * r.size,
                       (r.bounds.north - g.lat) / (r.bounds.north - r.bounds.south) * r.size,
                       g.h});
    }
    return out;
}

// Grid units a quantized vertex may move horizontally (as the encode tests allow).
double snap_reach(const TileRaster& r, const ErrorBudget& b) {
    const double rad = 3.14159265358979323846 / 180 * 6.3e6 / r.size;
    const double max_lat = std::max(std::abs(r.bounds.south), std::abs(r.bounds.north));
    const double cell = std::min((r.bounds.north - r.bounds.south) * rad,
                                 (r.bounds.east - r.bounds.west) * rad *
                                     std::cos(max_lat * 3.14159265358979323846 / 180));
    return b.quant_step * std::sqrt(3.0) / 2 * 1.01 / cell;
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const Bytes in{data, size};
    const TileRaster raster = raster_from(in);
    const double eps = 0.01 * std::ldexp(1.0, in.at(1) % 14);
    const ErrorBudget budget = tile_error_budget(eps, raster.scheme, raster.id.z, raster.size);
    const core::Mesh mesh = mesh_tile(raster, budget);
    core::check_mesh(mesh, raster.grid.width, raster.grid.height);
    for (Format f : {Format::Glb, Format::Drc}) {
        std::string bytes;
        try {
            bytes = encode_tile(raster, mesh, f, budget);
        } catch (const IoError&) {
            fail("encode_tile threw IoError");
        } catch (const Error&) {
            continue; // documented refusals: lattice too fine for the tile, a border cliff
        }
        DecodedTile d;
        try {
            d = f == Format::Glb ? decode_glb(bytes) : decode_drc(bytes);
        } catch (const std::exception& e) {
            std::fprintf(stderr, "fuzz_mesh: %s\n", e.what());
            fail("our own tile does not decode");
        }
        if (d.indices.size() != mesh.triangles.size()) {
            fail("triangle count changed in encoding", static_cast<double>(d.indices.size()));
        }
        for (std::uint32_t i : d.indices) {
            if (i >= d.positions.size()) {
                fail("decoded index out of range", i);
            }
        }
        for (const auto& p : d.positions) {
            if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) {
                fail("decoded position is not finite");
            }
        }
        const test::OracleResult res = test::linf_error(
            to_grid(d, f, raster), d.indices, raster.grid, snap_reach(raster, budget));
        if (res.uncovered > 0) {
            fail("decoded surface leaves samples uncovered", static_cast<double>(res.uncovered));
        }
        if (!(res.max_error <= budget.eps)) {
            std::fprintf(stderr,
                         "fuzz_mesh: %s tile %d/%lld/%lld size %d eps %.17g: error %.17g at "
                         "(%d, %d)\n",
                         f == Format::Glb ? "glb" : "drc",
                         raster.id.z,
                         static_cast<long long>(raster.id.x),
                         static_cast<long long>(raster.id.y),
                         raster.size,
                         budget.eps,
                         res.max_error,
                         res.worst_column,
                         res.worst_row);
            fail("decoded tile is not within eps");
        }
    }
    return 0;
}
