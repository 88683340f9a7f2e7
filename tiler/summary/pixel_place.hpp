#pragma once
// Where a summarised source's pixels lie (dem_summary.hpp): pixel (i, j)'s centre at integer
// (i, j), mapped to lon/lat either by an axis-aligned grid (PixelGrid: lon/lat degrees or
// EPSG:3857 metres) or, for any other georeferenced source (a UTM survey, a rotated grid),
// through the source's geotransform and CRS (DemSource::pixels_to_lonlat).
//
// Where the grid serves the scheme (summary_serves), a summary block is an axis-aligned box of
// the tile's grid and its plane stays a plane there. Elsewhere a block's place in the tile is
// curved, and summary_cells bounds that curve (projected_cells.hpp).
#include "tiler/sources/gdal_source.hpp"

#include <optional>
#include <string>
#include <vector>

namespace tb::tiler {

// True when the summary can serve `scheme`'s tiles of a source on `grid`: the pixel grid and
// the scheme's lattice are scaled copies of each other along both axes (a lon/lat grid for the
// geodetic scheme, an EPSG:3857 grid for mercator), so a block's plane stays a plane in the
// tile's grid coordinates.
bool summary_serves(const PixelGrid& grid, Scheme scheme);

// Source pixels per lattice step at zoom z (the smaller of the two axes).
double pixels_per_step(const PixelGrid& grid, Scheme scheme, int z, int size);

class PixelPlace {
public:
    // The source's pixel grid in `scheme` when it has one, else its CRS. Requires
    // source.georeferenced(); `source` must outlive the place. Not for a collection.
    PixelPlace(const DemSource& source, Scheme scheme);

    int width() const { return width_; }
    int height() const { return height_; }
    // The axis-aligned grid, when the source has one in this scheme.
    const std::optional<PixelGrid>& grid() const { return grid_; }
    // True when blocks are axis-aligned boxes with planes in the tile grids of the scheme it was
    // made for (summary_serves).
    bool serves() const { return serves_; }

    // Source pixels per lattice step at zoom z of `scheme`: the smaller axis on a grid that
    // serves it, else DemSource::pixels_per_sample.
    double pixels_per_step(Scheme scheme, int z, int size) const;
    // The lon/lat box of the pixel centres (DemSource::footprint).
    LonLatBox footprint() const;

    // Pixel coordinates to lon/lat in place, and back; NaN where a point does not transform.
    void to_lonlat(std::vector<double>& x, std::vector<double>& y) const;
    void to_pixels(std::vector<double>& x, std::vector<double>& y) const;

    // Lon/lat of the n points (i0 + k di, j), k = 0 .. n - 1, along one pixel row: moved through
    // the CRS at every s-th point and the last, s the most that keeps them within `span` pixels
    // of each other, and linear between (exact on an axis-aligned grid). A map projection bends
    // by about span^2 / (8 R) between them: 0.1 mm over 80 m.
    void row_to_lonlat(double i0,
                       double di,
                       double j,
                       int n,
                       double span,
                       std::vector<double>& lon,
                       std::vector<double>& lat) const;
    // The span that keeps the bend under 0.1 mm: 80 m of pixels, 1 to 8 of them.
    double fine_span() const { return fine_span_; }

    // What a stored summary's key says of the place (summary_file.hpp).
    std::string key() const;

private:
    const DemSource* source_;
    std::optional<PixelGrid> grid_;
    bool serves_ = false;
    int width_ = 0, height_ = 0;
    double fine_span_ = 1;
};

} // namespace tb::tiler
