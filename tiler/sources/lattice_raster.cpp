// Tile rasters from the zoom's lattice (lattice_raster.hpp).
#include "tiler/sources/lattice_raster.hpp"

#include "tiler/sources/geoid.hpp"

#include <cstdint>
#include <utility>
#include <vector>

namespace tb::tiler {

TileRaster lattice_tile_raster(const TileId& id,
                               const LatticeBlock& block,
                               Scheme scheme,
                               int tile_size,
                               VerticalDatum datum) {
    const int n = tile_size;
    const int m = kLatticeFillMargin;
    const int w = n + 1 + 2 * m;
    const std::int64_t c0 = block.column0, r0 = block.row0;

    // Undulation of every lattice point (the same for a point in every tile that holds it).
    std::vector<double> undulation(block.heights.size());
    for (int j = 0; j < w; ++j) {
        const double y = lattice_y(scheme, id.z, n, r0 + j);
        for (int i = 0; i < w; ++i) {
            const LonLat p = native_to_lonlat(scheme, lattice_x(scheme, id.z, n, c0 + i), y);
            undulation[static_cast<std::size_t>(j) * w + i] = egm96_undulation(p.lon, p.lat);
        }
    }
    // Fill voids in orthometric heights, so data-free areas sit on the geoid (sea level).
    std::vector<double> ortho = block.heights;
    if (datum == VerticalDatum::Ellipsoid) {
        for (std::size_t k = 0; k < ortho.size(); ++k) {
            ortho[k] -= block.valid[k] ? undulation[k] : 0.0;
        }
    }
    fill_voids(ortho, block.valid, w, w, m, 0.0);

    TileRaster raster;
    raster.id = id;
    raster.scheme = scheme;
    raster.bounds = tile_bounds(scheme, id);
    raster.size = n;
    raster.grid.width = n + 1;
    raster.grid.height = n + 1;
    raster.grid.heights.resize(static_cast<std::size_t>(n + 1) * (n + 1));
    std::vector<std::uint8_t> valid(raster.grid.heights.size());
    bool all_valid = true;
    for (int j = 0; j <= n; ++j) {
        for (int i = 0; i <= n; ++i) {
            const std::size_t k = static_cast<std::size_t>(j + m) * w + (i + m);
            const std::size_t t = static_cast<std::size_t>(j) * (n + 1) + i;
            const bool measured = block.valid[k] != 0;
            double h = ortho[k] + undulation[k];
            if (datum == VerticalDatum::Ellipsoid && measured) {
                h = block.heights[k]; // the source's own ellipsoidal height, untouched
            }
            raster.grid.heights[t] = static_cast<float>(h);
            valid[t] = measured ? 1 : 0;
            all_valid = all_valid && measured;
        }
    }
    if (!all_valid) {
        raster.grid.valid = std::move(valid);
    }
    return raster;
}

} // namespace tb::tiler
