#pragma once
// A layer's tile settings as a store manifest (tiler/stores/manifest.hpp): what decides the bytes
// of every tile the layer makes, so that a store never hands out a tile made to another bound.
#include "tiler/layer.hpp"
#include "tiler/stores/manifest.hpp"
#include "tiler/stores/store.hpp"

namespace tb::tiler {

// The entries that decide the bytes of every tile the layer makes, in this order: version (the
// revision: "0.1.0+" and a hash of core/ and tiler/'s sources, see CMakeLists.txt), layer, sources
// (absolute path, size and mtime of each local file), scheme, tile_size, effort, datum, min_zoom,
// max_zoom, eps (the ladder, one per zoom), eps_levels, nodata, and the DEM pyramid's
// dem_tile_size, dem_heights, dem_min_zoom, dem_max_zoom.
Manifest tile_settings(const Layer& layer);

// prepare_store_for_serving with the layer's name and tile settings.
inline StoreUse prepare_store_for_serving(TileStore& store, const Layer& layer) {
    return prepare_store_for_serving(store, layer.options().name, tile_settings(layer));
}

} // namespace tb::tiler
