// build --update: the tiles a change of DEMs touches (see update.hpp).
#include "tiler/pyramid/update.hpp"

#include "core/error.hpp"
#include "tiler/json_number.hpp"
#include "tiler/sources/gdal_source.hpp"
#include "tiler/summary/dem_summary.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <limits>
#include <set>
#include <tuple>

namespace tb::tiler {
namespace {

using nlohmann::json;

// Settings an update compares entry by entry; every other entry of a manifest, when it
// changed, changes every tile.
const std::set<std::string> kCompared = {"sources",
                                         "source_bounds",
                                         "source_grids",
                                         "data_bounds",
                                         "eps",
                                         "min_zoom",
                                         "max_zoom",
                                         "zooms",
                                         "dem_min_zoom",
                                         "dem_max_zoom",
                                         "mesh_ranges",
                                         "dem_ranges",
                                         "grid_origins",
                                         "summary_levels",
                                         "shard_count"};

json parse_entry(const Manifest& m, const std::string& key, const std::string& which) {
    const std::string text = manifest_value(m, key);
    const json value = json::parse(text, nullptr, false);
    if (text == "(absent)" || value.is_discarded()) {
        throw InputError("build --update: the " + which + " build manifest has no usable '" + key +
                         "' (it was made before --update existed); rebuild once with --force");
    }
    return value;
}

InputError unparsable(const std::string& which, const std::string& key) {
    return InputError("build --update: the " + which + " build manifest's " + key +
                      " do not parse; rebuild once with --force");
}

bool all_numbers(const json& a) {
    return std::all_of(a.begin(), a.end(), [](const json& v) { return v.is_number(); });
}

// The DEMs by path: their stamp (the "sources" entry) and bounds, in the manifest's order.
struct Dem {
    std::string path;
    std::string stamp;
    json bounds;
};

std::vector<Dem> dems_of(const Manifest& m, const std::string& which) {
    const json sources = parse_entry(m, "sources", which);
    const json bounds = parse_entry(m, "source_bounds", which);
    if (!sources.is_array() || !bounds.is_array() || bounds.size() != sources.size()) {
        throw InputError("build --update: the " + which +
                         " build manifest's sources and source_bounds disagree; rebuild once "
                         "with --force");
    }
    std::vector<Dem> out;
    for (std::size_t i = 0; i < sources.size(); ++i) {
        const json& source = sources[i];
        if (!source.is_object() || !source.contains("path") || !source["path"].is_string()) {
            throw unparsable(which, "sources");
        }
        out.push_back({source["path"].get<std::string>(), source.dump(), bounds[i]});
    }
    return out;
}

// Adds `dem`'s bounds to the scope's boxes; a DEM without bounds changes everything.
void add_bounds(UpdateScope& scope, const Dem& dem) {
    const json& b = dem.bounds;
    if (!b.is_array() || b.size() != 4 || !all_numbers(b)) {
        scope.everything = dem.path + " has no lon/lat bounds";
        return;
    }
    scope.boxes.push_back(
        {b[0].get<double>(), b[1].get<double>(), b[2].get<double>(), b[3].get<double>()});
}

// The DEMs added, removed or replaced, and whether the ones both builds have kept their order
// (which decides who wins where they overlap).
void compare_dems(UpdateScope& scope, const Manifest& was, const Manifest& now) {
    const std::vector<Dem> before = dems_of(was, "last"), after = dems_of(now, "new");
    std::vector<std::string> kept_before, kept_after;
    for (const Dem& d : after) {
        const auto old = std::find_if(
            before.begin(), before.end(), [&](const Dem& b) { return b.path == d.path; });
        if (old == before.end()) {
            scope.changes.push_back("added " + d.path);
            add_bounds(scope, d);
            continue;
        }
        kept_after.push_back(d.path);
        if (old->stamp != d.stamp || old->bounds != d.bounds) {
            scope.changes.push_back("replaced " + d.path);
            add_bounds(scope, *old);
            add_bounds(scope, d);
        }
    }
    for (const Dem& d : before) {
        const bool kept =
            std::any_of(after.begin(), after.end(), [&](const Dem& a) { return a.path == d.path; });
        if (kept) {
            kept_before.push_back(d.path);
        } else {
            scope.changes.push_back("removed " + d.path);
            add_bounds(scope, d);
        }
    }
    if (kept_before != kept_after) {
        scope.everything = "the DEMs are given in another order (which decides who wins)";
    }
}

// Each zoom's signature by zoom, as zooms_entry wrote them: arrays starting with z.
std::map<int, std::string>
signatures(const Manifest& m, const std::string& key, const std::string& which) {
    const json entry = parse_entry(m, key, which);
    if (!entry.is_array()) {
        throw unparsable(which, key);
    }
    std::map<int, std::string> out;
    for (const json& z : entry) {
        if (!z.is_array() || z.empty() || !z[0].is_number_integer()) {
            throw unparsable(which, key);
        }
        out[z[0].get<int>()] = z.dump();
    }
    return out;
}

// The eps a zoom signature names (its third element), as its text; empty when it has none.
std::string eps_in(const std::string& signature) {
    const json s = json::parse(signature, nullptr, false);
    return s.is_array() && s.size() > 2 && s[2].is_number() ? s[2].dump() : std::string();
}

// Zooms whose signature differs, or that only one manifest has. A moved eps joins `why`.
std::vector<int> changed_zooms(const Manifest& was,
                               const Manifest& now,
                               const std::string& key,
                               std::vector<std::string>& why) {
    const std::map<int, std::string> before = signatures(was, key, "last");
    const std::map<int, std::string> after = signatures(now, key, "new");
    std::set<int> out;
    for (const auto& [z, text] : before) {
        if (!after.count(z) || after.at(z) != text) {
            out.insert(z);
        }
        if (after.count(z) && eps_in(text) != eps_in(after.at(z))) {
            why.push_back("zoom " + std::to_string(z) + "'s eps moved from " + eps_in(text) +
                          " to " + eps_in(after.at(z)) + " m");
        }
    }
    for (const auto& [z, text] : after) {
        if (!before.count(z)) {
            out.insert(z);
        }
    }
    return {out.begin(), out.end()};
}

TileRange clipped(TileRange r, const TileRange& to) {
    r.x0 = std::max(r.x0, to.x0), r.y0 = std::max(r.y0, to.y0);
    r.x1 = std::min(r.x1, to.x1), r.y1 = std::min(r.y1, to.y1);
    return r;
}

bool inside(const TileRange& r, std::int64_t x, std::int64_t y) {
    return !r.empty() && x >= r.x0 && x <= r.x1 && y >= r.y0 && y <= r.y1;
}

// `a` less `b`, as up to four rectangles.
std::vector<TileRange> minus(const TileRange& a, const TileRange& b) {
    const TileRange cut = clipped(b, a);
    if (a.empty() || cut.empty()) {
        return {a};
    }
    std::vector<TileRange> out;
    const auto add = [&](std::int64_t x0, std::int64_t y0, std::int64_t x1, std::int64_t y1) {
        const TileRange r{a.z, x0, y0, x1, y1};
        if (!r.empty()) {
            out.push_back(r);
        }
    };
    add(a.x0, a.y0, a.x1, cut.y0 - 1);
    add(a.x0, cut.y1 + 1, a.x1, a.y1);
    add(a.x0, cut.y0, cut.x0 - 1, cut.y1);
    add(cut.x1 + 1, cut.y0, a.x1, cut.y1);
    return out;
}

// The tiles of zoom z meeting `box` widened by `around` of a tile.
TileRange tiles_reading(Scheme scheme, const LonLatBox& box, int z, double around) {
    const TileRange r = tiles_covering(scheme, box, z);
    if (r.empty()) {
        return r;
    }
    const LonLatBox a = tile_bounds(scheme, TileId{z, r.x0, r.y0});
    const LonLatBox b = tile_bounds(scheme, TileId{z, r.x1, r.y1});
    const double dx = (a.east - a.west) * around;
    const double dy = std::max(a.north - a.south, b.north - b.south) * around;
    return tiles_covering(
        scheme, {box.west - dx, box.south - dy, box.east + dx, box.north + dy}, z);
}

TileRange parents(const TileRange& r) {
    return TileRange{r.z - 1, r.x0 / 2, r.y0 / 2, r.x1 / 2, r.y1 / 2};
}

// `a` less `b`, as up to four boxes.
std::vector<LonLatBox> box_minus(const LonLatBox& a, const LonLatBox& b) {
    const LonLatBox cut{std::max(a.west, b.west),
                        std::max(a.south, b.south),
                        std::min(a.east, b.east),
                        std::min(a.north, b.north)};
    if (!(cut.west < cut.east && cut.south < cut.north)) {
        return {a};
    }
    std::vector<LonLatBox> out;
    const auto add = [&](double w, double s, double e, double n) {
        if (w < e && s < n) {
            out.push_back({w, s, e, n});
        }
    };
    add(a.west, a.south, a.east, cut.south);
    add(a.west, cut.north, a.east, a.north);
    add(a.west, cut.south, cut.west, cut.north);
    add(cut.east, cut.south, a.east, cut.north);
    return out;
}

// Where one of two boxes lies and the other does not joins the scope's boxes.
void add_difference(UpdateScope& scope, const LonLatBox& was, const LonLatBox& now) {
    if (was.west == now.west && was.south == now.south && was.east == now.east &&
        was.north == now.north) {
        return;
    }
    for (const auto& [a, b] : {std::pair{was, now}, std::pair{now, was}}) {
        for (const LonLatBox& piece : box_minus(a, b)) {
            scope.boxes.push_back(piece);
        }
    }
}

LonLatBox box_of(const Manifest& m, const std::string& key, const std::string& which) {
    const json b = parse_entry(m, key, which);
    if (!b.is_array() || b.size() != 4 || !all_numbers(b)) {
        throw unparsable(which, key);
    }
    return {b[0].get<double>(), b[1].get<double>(), b[2].get<double>(), b[3].get<double>()};
}

// A pixel grid as the manifest lists it: source_grids, grid_origins and summary_levels, one
// entry per grid in the same order.
struct Grid {
    double dx = 0, dy = 0;
    LonLatBox box;
    json origin;        // its grid_origins entry
    json summary_level; // its summary_levels entry
};

std::vector<Grid> grids_of(const Manifest& m, const std::string& which) {
    const json entry = parse_entry(m, "source_grids", which);
    const json origins = parse_entry(m, "grid_origins", which);
    const json levels = parse_entry(m, "summary_levels", which);
    if (!entry.is_array() || !origins.is_array() || !levels.is_array() ||
        origins.size() != entry.size() || levels.size() != entry.size()) {
        throw unparsable(which, "source_grids");
    }
    std::vector<Grid> out;
    for (std::size_t k = 0; k < entry.size(); ++k) {
        const json& g = entry[k];
        if (!g.is_array() || g.size() != 6 || !all_numbers(g)) {
            throw unparsable(which, "source_grids");
        }
        out.push_back(
            {g[0].get<double>(),
             g[1].get<double>(),
             {g[2].get<double>(), g[3].get<double>(), g[4].get<double>(), g[5].get<double>()},
             origins[k],
             levels[k]});
    }
    return out;
}

// A tile over the edge of a pixel grid meshes only the grid's pixels; inside a larger grid (a
// mosaic grown by a DEM) the same place is a void, filled. So where a grid's extent grew or
// shrank, the tiles change: the difference of its old and new extents joins the boxes. Grids
// are matched by pixel size and overlap; one without a match joins whole. Every tile changes
// when a matched grid's origin or summary level moved (every read is placed from the origin,
// and every block of the summary changes), when matched grids changed rank (the manifest lists
// them in rank order and the first wins where they overlap: a file of one grid listed before
// another grid's files moves it up), or when one grid becomes several or several one (a
// collection reads each zoom another way).
void compare_grids(UpdateScope& scope, const Manifest& was, const Manifest& now) {
    std::vector<Grid> before = grids_of(was, "last");
    const std::vector<Grid> after = grids_of(now, "new");
    if ((before.size() == 1) != (after.size() == 1)) {
        scope.everything = "the DEMs' " + std::to_string(before.size()) +
                           " pixel grid(s) are now " + std::to_string(after.size());
        return;
    }
    std::vector<bool> matched(before.size(), false);
    const auto meets = [](const LonLatBox& a, const LonLatBox& b) {
        return a.west <= b.east && b.west <= a.east && a.south <= b.north && b.south <= a.north;
    };
    std::size_t last_rank = 0; // 1 + the old rank of the last grid matched, in the new order
    for (const Grid& g : after) {
        std::size_t k = 0;
        while (k < before.size() && (matched[k] || before[k].dx != g.dx || before[k].dy != g.dy ||
                                     !meets(before[k].box, g.box))) {
            ++k;
        }
        if (k == before.size()) {
            scope.boxes.push_back(g.box);
            continue;
        }
        matched[k] = true;
        if (k + 1 < last_rank) {
            scope.everything = "the DEMs' pixel grids changed rank (the first wins where they "
                               "overlap)";
            return;
        }
        last_rank = k + 1;
        for (const auto& [key, was_entry, now_entry] :
             {std::tuple{"origin", &before[k].origin, &g.origin},
              std::tuple{"summary's finest level", &before[k].summary_level, &g.summary_level}}) {
            if (*was_entry != *now_entry) {
                scope.everything = std::string("a pixel grid's ") + key + " changed (was " +
                                   was_entry->dump() + ", now " + now_entry->dump() + ")";
                return;
            }
        }
        add_difference(scope, before[k].box, g.box);
    }
    for (std::size_t k = 0; k < before.size(); ++k) {
        if (!matched[k]) {
            scope.boxes.push_back(before[k].box);
        }
    }
    add_difference(scope, box_of(was, "data_bounds", "last"), box_of(now, "data_bounds", "new"));
}

} // namespace

std::string source_grids_entry(const Layer& layer) {
    std::string out = "[";
    for (const DemInfo* part : layer.source().parts()) {
        const auto& g = part->geotransform;
        const LonLatBox b = part->lonlat_bounds ? LonLatBox{(*part->lonlat_bounds)[0],
                                                            (*part->lonlat_bounds)[1],
                                                            (*part->lonlat_bounds)[2],
                                                            (*part->lonlat_bounds)[3]}
                                                : layer.source().footprint();
        out += (out.size() > 1 ? ", [" : "[") + json_number(g[1]) + ", " + json_number(g[5]) +
               ", " + json_number(b.west) + ", " + json_number(b.south) + ", " +
               json_number(b.east) + ", " + json_number(b.north) + "]";
    }
    return out + "]";
}

std::string box_entry(const LonLatBox& b) {
    return "[" + json_number(b.west) + ", " + json_number(b.south) + ", " + json_number(b.east) +
           ", " + json_number(b.north) + "]";
}

std::string source_bounds_entry(const std::vector<std::string>& sources) {
    std::string out = "[";
    for (std::size_t i = 0; i < sources.size(); ++i) {
        const DemInfo info = inspect_metadata(sources[i]);
        out += i ? ", " : "";
        if (const auto& b = info.lonlat_bounds) {
            out += box_entry({(*b)[0], (*b)[1], (*b)[2], (*b)[3]});
        } else {
            out += "null";
        }
    }
    return out + "]";
}

std::string ranges_entry(const std::vector<TileRange>& ranges) {
    std::string out = "[";
    for (std::size_t i = 0; i < ranges.size(); ++i) {
        const TileRange& r = ranges[i];
        out += (i ? ", [" : "[") + std::to_string(r.z) + ", " + std::to_string(r.x0) + ", " +
               std::to_string(r.y0) + ", " + std::to_string(r.x1) + ", " + std::to_string(r.y1) +
               "]";
    }
    return out + "]";
}

std::string zooms_entry(const Layer& layer, int from, int to) {
    std::string out = "[";
    for (int z = from; z <= to; ++z) {
        out += (z > from ? ", " : "") + layer.zoom_signature(z);
    }
    return out + "]";
}

std::string grid_origins_entry(const Layer& layer) {
    std::string out = "[";
    for (const DemInfo* part : layer.source().parts()) {
        const auto& g = part->geotransform;
        out += (out.size() > 1 ? ", [" : "[") + json_number(g[0]) + ", " + json_number(g[3]) +
               ", " + json_number(g[1]) + ", " + json_number(g[5]) + "]";
    }
    return out + "]";
}

std::string summary_levels_entry(const Layer& layer) {
    std::string out = "[";
    for (const DemInfo* part : layer.source().parts()) {
        out += (out.size() > 1 ? ", " : "") +
               std::to_string(summary_finest_level(part->width, part->height));
    }
    return out + "]";
}

std::vector<TileRange> parse_ranges(const std::string& entry, const std::string& what) {
    const json value = json::parse(entry, nullptr, false);
    std::vector<TileRange> out;
    const auto bad = [&] {
        return InputError("build --update: the " + what +
                          " in the build manifest do not parse; rebuild once with --force");
    };
    if (!value.is_array()) {
        throw bad();
    }
    for (const json& r : value) {
        if (!r.is_array() || r.size() != 5 ||
            !std::all_of(r.begin(), r.end(), [](const json& v) { return v.is_number_integer(); })) {
            throw bad();
        }
        out.push_back(TileRange{r[0].get<int>(),
                                r[1].get<std::int64_t>(),
                                r[2].get<std::int64_t>(),
                                r[3].get<std::int64_t>(),
                                r[4].get<std::int64_t>()});
        const TileRange& t = out.back();
        if (t.z < 0 || t.z > kMaxZoom) {
            throw bad();
        }
        // Columns and rows of either scheme lie in 0..2^(z+1) - 1; -1 is an empty range's edge.
        const std::int64_t limit = std::int64_t{2} << t.z;
        for (const std::int64_t v : {t.x0, t.y0, t.x1, t.y1}) {
            if (v < -1 || v >= limit) {
                throw bad();
            }
        }
    }
    return out;
}

// The first setting beyond those compared entry by entry that differs between the two
// manifests, in either direction (a setting cleared is a change too), as "KEY changed (was X,
// now Y)"; empty when none does.
std::string changed_setting(const Manifest& was, const Manifest& now) {
    for (const auto& [first, second] : {std::pair{&now, &was}, std::pair{&was, &now}}) {
        for (const auto& [key, value] : *first) {
            const std::string other = manifest_value(*second, key);
            if (kCompared.count(key) || other == value ||
                (key == "overlap" && other == "(absent)")) {
                continue; // one DEM has no overlap rule: adding a second does not change it
            }
            // A format or --bbox dropped would leave its tiles and documents behind.
            if (key == "formats" || key == "bbox") {
                throw InputError("build --update: " + key + " changed (was " +
                                 manifest_value(was, key) + ", now " + manifest_value(now, key) +
                                 "); an update keeps a build's formats and --bbox: rebuild with "
                                 "--force");
            }
            return key + " changed (was " + manifest_value(was, key) + ", now " +
                   manifest_value(now, key) + ")";
        }
    }
    return {};
}

UpdateScope update_scope(const Manifest& was, const Manifest& now) {
    UpdateScope scope;
    const std::string setting = changed_setting(was, now);
    compare_dems(scope, was, now); // the DEMs that changed, for the log, whatever else did
    if (!setting.empty()) {
        scope.everything = setting;
    }
    if (!scope.everything.empty()) {
        return scope;
    }
    compare_grids(scope, was, now);
    scope.zooms = changed_zooms(was, now, "zooms", scope.why);
    return scope;
}

UpdateTiles::UpdateTiles(const UpdateScope& scope,
                         Scheme scheme,
                         const std::vector<TileRange>& was,
                         const std::vector<TileRange>& now,
                         const std::vector<int>& zooms,
                         double around) {
    for (const TileRange& r : was) {
        was_[r.z] = r;
    }
    for (const TileRange& r : now) {
        now_[r.z] = r;
    }
    int finest = -1;
    for (const auto& m : {was_, now_}) {
        if (!m.empty()) {
            finest = std::max(finest, m.rbegin()->first);
        }
    }
    // From the finest zoom up, so that each zoom takes the parents of what its children got.
    std::vector<TileRange> carried; // touched tiles of the zoom below not under a DEM's box
    for (int z = finest; z >= 0; --z) {
        if (!was_.count(z) && !now_.count(z)) {
            for (TileRange& r : carried) {
                r = parents(r);
            }
            continue;
        }
        const TileRange empty{z, 0, 0, -1, -1};
        const TileRange a = was_.count(z) ? was_[z] : empty;
        const TileRange b = now_.count(z) ? now_[z] : empty;
        const TileRange span{z,
                             std::min(a.empty() ? b.x0 : a.x0, b.empty() ? a.x0 : b.x0),
                             std::min(a.empty() ? b.y0 : a.y0, b.empty() ? a.y0 : b.y0),
                             std::max(a.x1, b.x1),
                             std::max(a.y1, b.y1)};
        std::vector<TileRange> own;
        if (!scope.everything.empty() || std::count(zooms.begin(), zooms.end(), z)) {
            own.push_back(span);
        }
        for (const TileRange& r : minus(a, b)) {
            own.push_back(r);
        }
        for (const TileRange& r : minus(b, a)) {
            own.push_back(r);
        }
        for (const TileRange& r : carried) {
            own.push_back(r);
        }
        std::vector<TileRange>& here = touched_[z];
        for (const LonLatBox& box : scope.boxes) {
            // Widened to whole families: whether a tile exists below a coarser DEM's zoom
            // follows its family (LayerPlan::cover_at), so a file added or removed adds or
            // removes the siblings of the tiles under it too.
            here.push_back(clipped(whole_families(tiles_reading(scheme, box, z, around)), span));
        }
        carried.clear();
        for (const TileRange& r : own) {
            const TileRange c = clipped(r, span);
            if (!c.empty()) {
                here.push_back(c);
                carried.push_back(parents(c));
            }
        }
        std::erase_if(here, [](const TileRange& r) { return r.empty(); });
    }
}

bool UpdateTiles::contains(const TileId& id) const {
    const auto it = touched_.find(id.z);
    return it != touched_.end() &&
           std::any_of(it->second.begin(), it->second.end(), [&](const TileRange& r) {
               return inside(r, id.x, id.y);
           });
}

std::vector<TileRange> UpdateTiles::left_out_at(int z) const {
    const auto now = now_.find(z);
    std::vector<TileRange> out;
    for (const TileRange& r : touched_.at(z)) {
        for (const TileRange& piece : now == now_.end() ? std::vector{r} : minus(r, now->second)) {
            if (!piece.empty()) {
                out.push_back(piece);
            }
        }
    }
    return out;
}

std::int64_t UpdateTiles::left_out_count() const {
    std::int64_t n = 0;
    for (const auto& [z, ranges] : touched_) {
        n += union_count(left_out_at(z));
    }
    return n;
}

void UpdateTiles::for_each_left_out(const std::function<void(const TileId&)>& fn) const {
    for (const auto& [z, ranges] : touched_) {
        std::set<std::pair<std::int64_t, std::int64_t>> zoom; // one zoom's at a time
        for (const TileRange& piece : left_out_at(z)) {
            for (std::int64_t y = piece.y0; y <= piece.y1; ++y) {
                for (std::int64_t x = piece.x0; x <= piece.x1; ++x) {
                    zoom.insert({y, x});
                }
            }
        }
        for (const auto& [y, x] : zoom) {
            fn(TileId{z, x, y});
        }
    }
}

std::int64_t UpdateTiles::remade() const {
    std::int64_t n = 0;
    for (const auto& [z, range] : now_) {
        const auto it = touched_.find(z);
        if (it == touched_.end()) {
            continue;
        }
        std::vector<TileRange> rects;
        for (const TileRange& r : it->second) {
            if (const TileRange c = clipped(r, range); !c.empty()) {
                rects.push_back(c);
            }
        }
        n += union_count(rects);
    }
    return n;
}

} // namespace tb::tiler
