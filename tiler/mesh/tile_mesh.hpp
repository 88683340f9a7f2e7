#pragma once
// A tile's mesh as the formats encode it: vertices at the scheme's native coordinates, so a
// vertex shared by two neighbouring tiles has the same coordinates, bit for bit, in both.
#include "core/mesh.hpp"
#include "tiler/sources/tile_raster.hpp"

#include <cstdint>
#include <vector>

namespace tb::tiler {

struct TileMesh {
    // Native coordinates: degrees (geodetic) or EPSG:3857 metres (mercator).
    std::vector<double> x, y;
    std::vector<float> z; // metres above the WGS84 ellipsoid
    // 1 where the vertex lies on a border line it shares with a neighbouring tile (the tile's
    // edge, or a block edge where the two tiles meet): formats snap those to the level-wide
    // lattice, so both tiles decode them identically.
    std::vector<std::uint8_t> border;
    // Counter-clockwise seen from above (positive area in (x, y)); triangle t is 3t..3t+2.
    std::vector<core::Index> triangles;

    std::size_t vertex_count() const { return x.size(); }
    std::size_t triangle_count() const { return triangles.size() / 3; }
    // Appends a vertex and returns its index.
    core::Index add(double vx, double vy, float vz, bool on_border);
};

// The mesh of `raster` (meshed by core from raster.grid) at the raster's sample positions. A
// vertex is on the border when it lies on the grid's outer rows or columns. With drop_voids,
// triangles that hold no valid sample (all three vertices and everything inside them void) are
// left out: 3D Tiles content may have holes, and there is no data to draw there.
TileMesh to_tile_mesh(const TileRaster& raster, const core::Mesh& mesh, bool drop_voids);

// True when the closed triangle (a, b, c) of grid points holds a valid sample of grid.
bool holds_valid_sample(const core::HeightGrid& grid,
                        core::GridPoint a,
                        core::GridPoint b,
                        core::GridPoint c);

// Removes the vertices no triangle uses, keeping the order of the others.
void drop_unused_vertices(TileMesh& mesh);

// Gives each vertex whose triangles form more than one fan (two groups touching only at it,
// which dropping void triangles can leave) a copy per extra fan, so every vertex is manifold, as
// Draco's mesh coder needs (it would split such a vertex itself and change the vertex count).
void split_nonmanifold_vertices(TileMesh& mesh);

// The grid coordinates (column, row) of vertex v of mesh in raster's frame.
void vertex_grid_position(
    const TileRaster& raster, const TileMesh& mesh, std::size_t v, double& column, double& row);

} // namespace tb::tiler
