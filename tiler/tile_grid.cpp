// Tile pyramid arithmetic: geodetic (EPSG:4326, 2x1 roots, TMS) and mercator (EPSG:3857, XYZ).
#include "tiler/tile_grid.hpp"

#include "core/error.hpp"

#include <algorithm>
#include <cmath>

namespace tb::tiler {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kEarthRadius = 6378137.0;            // EPSG:3857 sphere
constexpr double kMercatorHalf = kPi * kEarthRadius;  // 20037508.342789244 m
constexpr double kMercatorMaxLat = 85.05112877980659; // atan(sinh(pi)) in degrees

double mercator_y_to_lat(double y) {
    return std::atan(std::sinh(y / kEarthRadius)) * 180.0 / kPi;
}

double lat_to_mercator_y(double lat) {
    const double phi = std::clamp(lat, -kMercatorMaxLat, kMercatorMaxLat) * kPi / 180.0;
    return kEarthRadius * std::log(std::tan(kPi / 4 + phi / 2));
}

// Index range [i0, i1] of the cells of width `step` starting at `origin` that the open
// interval (lo, hi) overlaps, clamped to [0, n-1]. A box that only touches a cell's edge does
// not select that cell.
void cells_overlapping(double lo,
                       double hi,
                       double origin,
                       double step,
                       std::int64_t n,
                       std::int64_t& i0,
                       std::int64_t& i1) {
    const double a = (lo - origin) / step;
    const double b = (hi - origin) / step;
    i0 = static_cast<std::int64_t>(std::floor(a));
    i1 = static_cast<std::int64_t>(std::ceil(b)) - 1;
    i0 = std::clamp<std::int64_t>(i0, 0, n - 1);
    i1 = std::clamp<std::int64_t>(i1, -1, n - 1);
}

} // namespace

Scheme parse_scheme(std::string_view name) {
    if (name == "geodetic") {
        return Scheme::Geodetic;
    }
    if (name == "mercator") {
        return Scheme::Mercator;
    }
    throw InputError("scheme '" + std::string(name) + "': expected 'geodetic' or 'mercator'");
}

const char* to_string(Scheme scheme) {
    return scheme == Scheme::Geodetic ? "geodetic" : "mercator";
}

std::int64_t tiles_across(Scheme scheme, int z) {
    TB_ASSERT(z >= 0 && z <= kMaxZoom);
    return scheme == Scheme::Geodetic ? (std::int64_t{2} << z) : (std::int64_t{1} << z);
}

std::int64_t tiles_down(Scheme, int z) {
    TB_ASSERT(z >= 0 && z <= kMaxZoom);
    return std::int64_t{1} << z;
}

namespace {

bool is_valid(Scheme scheme, const TileId& id) {
    if (id.z < 0 || id.z > kMaxZoom) {
        return false;
    }
    return id.x >= 0 && id.y >= 0 && id.x < tiles_across(scheme, id.z) &&
           id.y < tiles_down(scheme, id.z);
}

// Whether a range's tiles all lie in the scheme (an empty range does). Used by assertions only.
[[maybe_unused]] bool in_scheme(Scheme scheme, const TileRange& r) {
    return r.empty() ||
           (is_valid(scheme, {r.z, r.x0, r.y0}) && is_valid(scheme, {r.z, r.x1, r.y1}));
}

} // namespace

std::string tile_name(const TileId& id) {
    return std::to_string(id.z) + "/" + std::to_string(id.x) + "/" + std::to_string(id.y);
}

std::optional<ValidTile> ValidTile::of(Scheme scheme, const TileId& id) {
    if (!is_valid(scheme, id)) {
        return std::nullopt;
    }
    return ValidTile(scheme, id);
}

ValidTile ValidTile::parse(Scheme scheme, const TileId& id) {
    if (const std::optional<ValidTile> tile = of(scheme, id)) {
        return *tile;
    }
    const std::string where =
        "tile " + tile_name(id) + " is outside the " + to_string(scheme) + " scheme: ";
    if (id.z < 0 || id.z > kMaxZoom) {
        throw InputError(where + "zoom " + std::to_string(id.z) + " is outside 0.." +
                         std::to_string(kMaxZoom));
    }
    throw InputError(where + "at zoom " + std::to_string(id.z) + ", x is 0.." +
                     std::to_string(tiles_across(scheme, id.z) - 1) + " and y is 0.." +
                     std::to_string(tiles_down(scheme, id.z) - 1));
}

ValidTile ValidTile::in_range(Scheme scheme, const TileRange& range, std::int64_t k) {
    TB_ASSERT(in_scheme(scheme, range));
    TB_ASSERT(k >= 0 && k < range.count());
    const std::int64_t width = range.x1 - range.x0 + 1;
    return ValidTile(scheme, {range.z, range.x0 + k % width, range.y0 + k / width});
}

std::optional<ValidTile> ValidTile::parent() const {
    if (id_.z == 0) {
        return std::nullopt;
    }
    return ValidTile(scheme_, {id_.z - 1, id_.x / 2, id_.y / 2});
}

std::vector<ValidTile> ValidTile::children() const {
    std::vector<ValidTile> out;
    if (id_.z == kMaxZoom) {
        return out;
    }
    // Each zoom has twice the columns and rows of the one above in both schemes.
    for (std::int64_t dy = 0; dy < 2; ++dy) {
        for (std::int64_t dx = 0; dx < 2; ++dx) {
            out.push_back(ValidTile(scheme_, {id_.z + 1, 2 * id_.x + dx, 2 * id_.y + dy}));
        }
    }
    return out;
}

std::vector<ValidTile> tiles_in(Scheme scheme, const TileRange& range) {
    std::vector<ValidTile> out;
    out.reserve(static_cast<std::size_t>(range.count()));
    for (std::int64_t k = 0; k < range.count(); ++k) {
        out.push_back(ValidTile::in_range(scheme, range, k));
    }
    return out;
}

LonLatBox tile_bounds(Scheme scheme, const TileId& id) {
    TB_ASSERT(is_valid(scheme, id));
    if (scheme == Scheme::Geodetic) {
        const double w = 180.0 / static_cast<double>(std::int64_t{1} << id.z);
        return {-180.0 + static_cast<double>(id.x) * w,
                -90.0 + static_cast<double>(id.y) * w,
                -180.0 + static_cast<double>(id.x + 1) * w,
                -90.0 + static_cast<double>(id.y + 1) * w};
    }
    const double w = 2 * kMercatorHalf / static_cast<double>(std::int64_t{1} << id.z);
    const double west = -kMercatorHalf + static_cast<double>(id.x) * w;
    const double east = -kMercatorHalf + static_cast<double>(id.x + 1) * w;
    const double north = kMercatorHalf - static_cast<double>(id.y) * w;
    const double south = kMercatorHalf - static_cast<double>(id.y + 1) * w;
    return {west * 180.0 / kMercatorHalf,
            mercator_y_to_lat(south),
            east * 180.0 / kMercatorHalf,
            mercator_y_to_lat(north)};
}

TileRange tiles_covering(Scheme scheme, const LonLatBox& box, int z) {
    TB_ASSERT(z >= 0 && z <= kMaxZoom);
    TileRange range;
    range.z = z;
    if (!(box.west < box.east) || !(box.south < box.north)) {
        return range; // empty (also for NaN)
    }
    const std::int64_t nx = tiles_across(scheme, z);
    const std::int64_t ny = tiles_down(scheme, z);
    if (scheme == Scheme::Geodetic) {
        const double w = 180.0 / static_cast<double>(std::int64_t{1} << z);
        cells_overlapping(box.west, box.east, -180.0, w, nx, range.x0, range.x1);
        cells_overlapping(box.south, box.north, -90.0, w, ny, range.y0, range.y1);
        return range;
    }
    const double w = 2 * kMercatorHalf / static_cast<double>(std::int64_t{1} << z);
    const double west = box.west / 180.0 * kMercatorHalf;
    const double east = box.east / 180.0 * kMercatorHalf;
    cells_overlapping(west, east, -kMercatorHalf, w, nx, range.x0, range.x1);
    // Rows count from the north: row r spans y in [H - (r+1)w, H - r w].
    const double north = lat_to_mercator_y(box.north);
    const double south = lat_to_mercator_y(box.south);
    if (!(south < north)) {
        return TileRange{z, 0, 0, -1, -1}; // box entirely beyond the mercator latitude limit
    }
    cells_overlapping(-north, -south, -kMercatorHalf, w, ny, range.y0, range.y1);
    return range;
}

TileRange bounding(int z, const std::vector<TileRange>& ranges) {
    TileRange out{z, 0, 0, -1, -1};
    for (const TileRange& r : ranges) {
        if (r.empty()) {
            continue;
        }
        out = out.empty() ? r
                          : TileRange{z,
                                      std::min(out.x0, r.x0),
                                      std::min(out.y0, r.y0),
                                      std::max(out.x1, r.x1),
                                      std::max(out.y1, r.y1)};
    }
    return out;
}

std::int64_t union_count(const std::vector<TileRange>& rects) {
    return TileCover(0, rects).count();
}

namespace {

using Spans = std::vector<std::pair<std::int64_t, std::int64_t>>;

// The union of the column spans of `active`, sorted and apart (touching spans joined).
Spans merged_spans(const std::vector<const TileRange*>& active) {
    Spans spans;
    spans.reserve(active.size());
    for (const TileRange* r : active) {
        spans.push_back({r->x0, r->x1});
    }
    std::sort(spans.begin(), spans.end());
    Spans out;
    for (const auto& s : spans) {
        if (!out.empty() && s.first <= out.back().second + 1) {
            out.back().second = std::max(out.back().second, s.second);
        } else {
            out.push_back(s);
        }
    }
    return out;
}

} // namespace

// A sweep over the rows where ranges start or end: between two such rows the same ranges are
// active, so one band holds their merged spans (never a walk over every tile of the zoom).
TileCover::TileCover(int z, const std::vector<TileRange>& ranges) : z_(z) {
    std::vector<const TileRange*> by_start;
    std::vector<std::int64_t> rows;
    for (const TileRange& r : ranges) {
        if (!r.empty()) {
            by_start.push_back(&r);
            rows.push_back(r.y0);
            rows.push_back(r.y1 + 1);
        }
    }
    std::sort(by_start.begin(), by_start.end(), [](const TileRange* a, const TileRange* b) {
        return a->y0 < b->y0;
    });
    std::sort(rows.begin(), rows.end());
    rows.erase(std::unique(rows.begin(), rows.end()), rows.end());
    std::vector<const TileRange*> active;
    std::size_t next = 0;
    for (std::size_t i = 0; i + 1 < rows.size(); ++i) {
        const std::int64_t y0 = rows[i], y1 = rows[i + 1] - 1;
        std::erase_if(active, [&](const TileRange* r) { return r->y1 < y0; });
        for (; next < by_start.size() && by_start[next]->y0 <= y0; ++next) {
            active.push_back(by_start[next]);
        }
        if (active.empty()) {
            continue;
        }
        Spans spans = merged_spans(active);
        if (!bands_.empty() && bands_.back().y1 + 1 == y0 && bands_.back().spans == spans) {
            bands_.back().y1 = y1;
        } else {
            bands_.push_back(Band{y0, y1, std::move(spans)});
        }
    }
}

bool TileCover::contains(std::int64_t x, std::int64_t y) const {
    const auto band = std::upper_bound(
        bands_.begin(), bands_.end(), y, [](std::int64_t v, const Band& b) { return v < b.y0; });
    if (band == bands_.begin() || y > std::prev(band)->y1) {
        return false;
    }
    const Spans& spans = std::prev(band)->spans;
    const auto span = std::upper_bound(
        spans.begin(), spans.end(), x, [](std::int64_t v, const auto& s) { return v < s.first; });
    return span != spans.begin() && x <= std::prev(span)->second;
}

std::int64_t TileCover::count() const {
    std::int64_t n = 0;
    for (const Band& b : bands_) {
        for (const auto& [x0, x1] : b.spans) {
            n += (x1 - x0 + 1) * (b.y1 - b.y0 + 1);
        }
    }
    return n;
}

TileRange TileCover::bounding() const {
    return tiler::bounding(z_, ranges());
}

std::vector<TileRange> TileCover::ranges_within(const TileRange& window) const {
    std::vector<TileRange> out;
    if (window.empty()) {
        return out;
    }
    // Bands are apart and sorted, so their last rows are sorted too; so are a band's spans.
    auto band = std::lower_bound(bands_.begin(),
                                 bands_.end(),
                                 window.y0,
                                 [](const Band& b, std::int64_t y) { return b.y1 < y; });
    for (; band != bands_.end() && band->y0 <= window.y1; ++band) {
        auto span = std::lower_bound(band->spans.begin(),
                                     band->spans.end(),
                                     window.x0,
                                     [](const auto& s, std::int64_t x) { return s.second < x; });
        for (; span != band->spans.end() && span->first <= window.x1; ++span) {
            out.push_back(TileRange{z_,
                                    std::max(span->first, window.x0),
                                    std::max(band->y0, window.y0),
                                    std::min(span->second, window.x1),
                                    std::min(band->y1, window.y1)});
        }
    }
    return out;
}

std::vector<TileRange> TileCover::ranges() const {
    std::vector<TileRange> out;
    for (const Band& b : bands_) {
        for (const auto& [x0, x1] : b.spans) {
            out.push_back(TileRange{z_, x0, b.y0, x1, b.y1});
        }
    }
    return out;
}

TileRange tiles_in_families(Scheme scheme, const LonLatBox& deep, const LonLatBox& all, int z) {
    TileRange r = tiles_covering(scheme, deep, z);
    if (r.empty() || z == 0) {
        return r;
    }
    const TileRange cut = tiles_covering(scheme, all, z);
    r = whole_families(r);
    r.x0 = std::max(r.x0, cut.x0), r.x1 = std::min(r.x1, cut.x1);
    r.y0 = std::max(r.y0, cut.y0), r.y1 = std::min(r.y1, cut.y1);
    return r;
}

TileRange whole_families(TileRange r) {
    if (r.z > 0 && !r.empty()) {
        r.x0 &= ~std::int64_t{1}, r.y0 &= ~std::int64_t{1};
        r.x1 |= 1, r.y1 |= 1;
    }
    return r;
}

} // namespace tb::tiler
