#include "tiler/sources/collection_source.hpp"

#include "core/error.hpp"
#include "tiler/sources/source_list.hpp"

#include <algorithm>
#include <cmath>
#include <optional>
#include <string>

namespace tb::tiler {
namespace {

bool meets(const LonLatBox& a, const LonLatBox& b) {
    return a.west <= b.east && b.west <= a.east && a.south <= b.north && b.south <= a.north;
}

// How fine a member is: its pixels per sample of one lattice (geodetic zoom 10), which for
// lon/lat DEMs does not depend on latitude, so two of one angular pixel size tie.
double fineness(const DemSource& m) {
    return m.pixels_per_sample(Scheme::Geodetic, 10, 256);
}

LonLatBox united(const LonLatBox& a, const LonLatBox& b) {
    return {std::min(a.west, b.west),
            std::min(a.south, b.south),
            std::max(a.east, b.east),
            std::max(a.north, b.north)};
}

// The collection's description: what a layer plans with (the finest member's resolution, the
// union of footprints and height ranges) and what `info` prints.
DemInfo describe_members(const std::vector<std::shared_ptr<const DemSource>>& members) {
    const DemInfo& first = members.front()->info();
    DemInfo out = first;
    out.driver = "collection";
    std::vector<std::string> names;
    for (std::size_t k = 0; k < members.size(); ++k) {
        const DemInfo& m = members[k]->info();
        names.push_back(m.path);
        if (m.resolution_m < out.resolution_m) {
            out.width = m.width, out.height = m.height, out.geotransform = m.geotransform;
            out.resolution_m = m.resolution_m;
        }
        if (m.data_type != out.data_type || m.scale != out.scale) {
            out.data_type = "mixed"; // no common height step
        }
        if (m.crs_name != out.crs_name) {
            out.crs_name = "mixed", out.crs_id.clear();
        }
        out.geographic = out.geographic && m.geographic;
        out.range_exact = out.range_exact && m.range_exact;
        if (m.has_data) {
            out.min_height = out.has_data ? std::min(out.min_height, m.min_height) : m.min_height;
            out.max_height = out.has_data ? std::max(out.max_height, m.max_height) : m.max_height;
            out.has_data = true;
        }
        out.outliers += k > 0 ? m.outliers : 0; // the first's are out's already
    }
    out.path = inputs_text(names);
    out.files.clear();
    for (const auto& m : members) {
        out.files.insert(out.files.end(), m->info().files.begin(), m->info().files.end());
    }
    // Between members lie voids, filled as nodata is.
    out.nodata = first.nodata.value_or(-32768.0);
    out.likely_nodata.reset();
    return out;
}

class CollectionSource final : public DemSource {
public:
    explicit CollectionSource(std::vector<std::shared_ptr<const DemSource>> members)
        : members_(std::move(members)), info_(describe_members(members_)) {
        for (std::size_t k = 1; k < members_.size(); ++k) {
            if (fineness(*members_[k]) > fineness(*members_[finest_])) {
                finest_ = k;
            }
        }
        footprint_ = members_.front()->footprint();
        for (const auto& m : members_) {
            footprint_ = united(footprint_, m->footprint());
        }
        info_.lonlat_bounds = std::array<double, 4>{
            footprint_.west, footprint_.south, footprint_.east, footprint_.north};
    }

    const DemInfo& info() const override { return info_; }
    std::vector<const DemInfo*> parts() const override {
        std::vector<const DemInfo*> out;
        for (const auto& m : members_) {
            out.push_back(&m->info());
        }
        return out;
    }
    std::vector<std::shared_ptr<const DemSource>> members() const override { return members_; }
    std::vector<FileOverlap> overlaps() const override {
        std::vector<FileOverlap> out;
        for (const auto& m : members_) {
            const std::vector<FileOverlap> each = m->overlaps();
            out.insert(out.end(), each.begin(), each.end());
        }
        return out;
    }
    bool georeferenced() const override { return true; }
    LonLatBox footprint() const override { return footprint_; }
    bool ellipsoidal_heights() const override { return members_.front()->ellipsoidal_heights(); }

    std::vector<LonLatBox> footprints_at(Scheme scheme, int z, int size) const override;

    // The finest member's: the pyramid goes as deep as the finest data.
    double pixels_per_sample(Scheme scheme, int z, int size) const override {
        return members_[finest_]->pixels_per_sample(scheme, z, size);
    }
    ReadLevel read_level(Scheme scheme, int z, int size) const override {
        return members_[finest_]->read_level(scheme, z, size);
    }
    double tile_pixels(Scheme scheme, int z, int size) const override {
        double sum = 0;
        for (const auto& m : members_) {
            sum += m->tile_pixels(scheme, z, size);
        }
        return sum;
    }

    LatticeBlock sample(Scheme scheme,
                        int z,
                        int size,
                        std::int64_t column0,
                        std::int64_t row0,
                        int width,
                        int height) const override;

    std::optional<PixelGrid> pixel_grid(Scheme) const override { return std::nullopt; }
    std::vector<double> read_pixels(std::int64_t, std::int64_t, int, int) const override {
        TB_ASSERT(!"read_pixels needs pixel_grid(), which a collection has not");
        return {};
    }
    bool window_empty(std::int64_t, std::int64_t, int, int) const override { return false; }
    void pixels_to_lonlat(std::vector<double>&, std::vector<double>&) const override {
        TB_ASSERT(!"a collection has no pixels of its own; its members have");
    }
    void lonlat_to_pixels(std::vector<double>&, std::vector<double>&) const override {
        TB_ASSERT(!"a collection has no pixels of its own; its members have");
    }

    void pixels_in(const LonLatBox& box, const PixelVisitor& visit) const override;
    std::size_t window_pixels(const LonLatBox& box) const override {
        std::size_t sum = 0;
        for (const auto& m : members_) {
            if (meets(m->footprint(), box)) {
                sum += m->window_pixels(box);
            }
        }
        return sum;
    }
    std::unique_ptr<const PixelCoverage> coverage(const LonLatBox& box) const override;

    core::HeightGrid read_all() const override {
        throw InputError(info_.path + ": a collection of DEMs cannot be meshed whole; give one "
                                      "DEM, or tile the collection (terrabound tile/build)");
    }

private:
    std::vector<std::shared_ptr<const DemSource>> members_; // ranked, first wins
    std::size_t finest_ = 0; // the member with the most pixels per lattice sample
    DemInfo info_;
    LonLatBox footprint_;
};

// The files of the members whose own pyramid reaches zoom z (the first zoom whose lattice is as
// fine as their pixels, as LayerPlan plans max_zoom), or past the deepest, the deepest ones.
std::vector<LonLatBox> CollectionSource::footprints_at(Scheme scheme, int z, int size) const {
    std::vector<int> deepest;
    for (const auto& m : members_) {
        deepest.push_back(native_zoom(*m, scheme, size));
    }
    const int reach = std::min(z, *std::max_element(deepest.begin(), deepest.end()));
    std::vector<LonLatBox> out;
    for (std::size_t m = 0; m < members_.size(); ++m) {
        if (deepest[m] >= reach) {
            const std::vector<LonLatBox> each = members_[m]->footprints_at(scheme, z, size);
            out.insert(out.end(), each.begin(), each.end());
        }
    }
    return out;
}

// Each lattice point takes the first member whose sample there is valid.
LatticeBlock CollectionSource::sample(Scheme scheme,
                                      int z,
                                      int size,
                                      std::int64_t column0,
                                      std::int64_t row0,
                                      int width,
                                      int height) const {
    LatticeBlock out = members_.front()->sample(scheme, z, size, column0, row0, width, height);
    for (std::size_t m = 1; m < members_.size(); ++m) {
        if (std::all_of(out.valid.begin(), out.valid.end(), [](std::uint8_t v) { return v; })) {
            break;
        }
        const LatticeBlock below =
            members_[m]->sample(scheme, z, size, column0, row0, width, height);
        for (std::size_t k = 0; k < out.valid.size(); ++k) {
            if (!out.valid[k] && below.valid[k]) {
                out.heights[k] = below.heights[k];
                out.valid[k] = 1;
            }
        }
    }
    return out;
}

// Every member's valid pixels in `box`, less those lying in a valid pixel of a higher member,
// a batch at a time so that the list held stays small.
void CollectionSource::pixels_in(const LonLatBox& box, const PixelVisitor& visit) const {
    constexpr std::size_t kBatch = 65536;
    std::vector<std::unique_ptr<const PixelCoverage>> above;
    std::vector<SourcePixel> batch;
    std::vector<double> lons, lats;
    std::vector<std::uint8_t> covered;
    const auto flush = [&] {
        lons.resize(batch.size()), lats.resize(batch.size());
        for (std::size_t k = 0; k < batch.size(); ++k) {
            lons[k] = batch[k].lon, lats[k] = batch[k].lat;
        }
        covered.assign(batch.size(), 0);
        for (const auto& c : above) {
            c->mark(lons, lats, covered);
        }
        for (std::size_t k = 0; k < batch.size(); ++k) {
            if (!covered[k]) {
                visit(batch[k]);
            }
        }
        batch.clear();
    };
    for (std::size_t k = 0; k < members_.size(); ++k) {
        const DemSource& m = *members_[k];
        if (!meets(m.footprint(), box)) {
            continue;
        }
        if (above.empty()) {
            m.pixels_in(box, visit);
        } else {
            m.pixels_in(box, [&](const SourcePixel& p) {
                batch.push_back(p);
                if (batch.size() == kBatch) {
                    flush();
                }
            });
            flush();
        }
        if (k + 1 < members_.size()) { // the last member covers no one
            above.push_back(m.coverage(box));
        }
    }
}

// Covered where any member covers.
class CollectionCoverage final : public PixelCoverage {
public:
    explicit CollectionCoverage(std::vector<std::unique_ptr<const PixelCoverage>> parts)
        : parts_(std::move(parts)) {}
    void mark(const std::vector<double>& lons,
              const std::vector<double>& lats,
              std::vector<std::uint8_t>& covered) const override {
        for (const auto& p : parts_) {
            p->mark(lons, lats, covered);
        }
    }

private:
    std::vector<std::unique_ptr<const PixelCoverage>> parts_;
};

std::unique_ptr<const PixelCoverage> CollectionSource::coverage(const LonLatBox& box) const {
    std::vector<std::unique_ptr<const PixelCoverage>> parts;
    for (const auto& m : members_) {
        if (meets(m->footprint(), box)) {
            parts.push_back(m->coverage(box));
        }
    }
    return std::make_unique<CollectionCoverage>(std::move(parts));
}

} // namespace

SourcePriority parse_source_priority(const std::string& text, const std::string& what) {
    if (text == "finest") {
        return SourcePriority::Finest;
    }
    if (text == "listed") {
        return SourcePriority::Listed;
    }
    throw InputError(what + ": '" + text +
                     "' is not a priority; use 'finest' (the finer DEM wins where DEMs overlap) "
                     "or 'listed' (the first given wins)");
}

const char* to_string(SourcePriority priority) {
    return priority == SourcePriority::Finest ? "finest" : "listed";
}

std::shared_ptr<const DemSource>
make_collection_source(std::vector<std::shared_ptr<const DemSource>> members,
                       SourcePriority priority) {
    TB_ASSERT(members.size() >= 2);
    for (const auto& m : members) {
        if (!m->georeferenced()) {
            throw InputError(m->info().path + ": has no georeferencing; a collection of DEMs "
                                              "needs a CRS and geotransform in each");
        }
        if (m->ellipsoidal_heights() != members.front()->ellipsoidal_heights()) {
            throw InputError(m->info().path + ": its heights are " +
                             (m->ellipsoidal_heights() ? "ellipsoidal" : "orthometric") + " and " +
                             members.front()->info().path +
                             "'s are not; convert the DEMs to one vertical datum");
        }
    }
    if (priority == SourcePriority::Finest) {
        std::stable_sort(members.begin(), members.end(), [](const auto& a, const auto& b) {
            return fineness(*a) > fineness(*b);
        });
    }
    return std::make_shared<CollectionSource>(std::move(members));
}

} // namespace tb::tiler
