// The summaries of a collection's members (member_summaries.hpp).
#include "tiler/summary/member_summaries.hpp"

#include "core/error.hpp"
#include "tiler/summary/layer_summary.hpp"
#include "tiler/summary/summary_tile.hpp"

#include <algorithm>
#include <cmath>

namespace tb::tiler {
namespace {

bool meets(const LonLatBox& a, const LonLatBox& b) {
    return a.west <= b.east && b.west <= a.east && a.south <= b.north && b.south <= a.north;
}

} // namespace

MemberSummaries::MemberSummaries(const LayerOptions& options,
                                 const DemSource& collection,
                                 VerticalDatum datum)
    : options_(options), datum_(datum) {
    for (auto& source : collection.members()) {
        auto m = std::make_unique<Member>();
        m->place.emplace(*source, options_.scheme);
        m->source = std::move(source);
        members_.push_back(std::move(m));
    }
    TB_ASSERT(members_.size() >= 2);
}

const DemSummary& MemberSummaries::summary(const Member& m) const {
    std::call_once(m.once, [&] {
        m.summary.emplace(
            load_or_make_summary(options_, m.source->info().files, *m.source, *m.place, datum_));
    });
    return *m.summary;
}

// The rule one DEM's layer follows (LayerPlan::zoom_source for its tiles, Layer::sample for other
// lattices): pixels per lattice step on a grid that serves the scheme, else pixels per sample.
int MemberSummaries::level(const Member& m, Scheme scheme, int z, int size) const {
    const double pps = m.place->pixels_per_step(scheme, z, size);
    if (pps < std::exp2(kFinestLevel)) {
        return -1;
    }
    return summary_level(summary(m), pps);
}

bool MemberSummaries::reads_summary(std::size_t m, int z) const {
    const Member& member = *members_.at(m);
    return member.place->pixels_per_step(options_.scheme, z, options_.tile_size) >=
           std::exp2(kFinestLevel);
}

void MemberSummaries::prepare(int z0, int z1) const {
    for (std::size_t m = 0; m < members_.size(); ++m) {
        for (int z = z0; z <= z1; ++z) {
            if (reads_summary(m, z)) {
                summary(*members_[m]);
                break;
            }
        }
    }
}

double MemberSummaries::zoom_reach(int z, int coarsest) const {
    TileRoughness roughest;
    for (std::size_t m = 0; m < members_.size(); ++m) {
        if (reads_summary(m, coarsest)) {
            const Member& member = *members_[m];
            add_roughness(
                summary(member), *member.place, options_.scheme, z, options_.tile_size, roughest);
        }
    }
    return median_roughness(roughest);
}

bool MemberSummaries::reads_summaries(int z) const {
    for (std::size_t m = 0; m < members_.size(); ++m) {
        if (reads_summary(m, z)) {
            return true;
        }
    }
    return false;
}

double MemberSummaries::tile_pixels(int z) const {
    double sum = 0;
    for (std::size_t m = 0; m < members_.size(); ++m) {
        if (!reads_summary(m, z)) {
            sum += members_[m]->source->tile_pixels(options_.scheme, z, options_.tile_size);
        }
    }
    return sum;
}

LatticeBlock MemberSummaries::sample(Scheme scheme,
                                     int z,
                                     int size,
                                     std::int64_t column0,
                                     std::int64_t row0,
                                     int width,
                                     int height) const {
    const auto read = [&](const Member& m) {
        const int at = level(m, scheme, z, size);
        if (at < 0) {
            return m.source->sample(scheme, z, size, column0, row0, width, height);
        }
        return summary_lattice(
            summary(m), *m.place, datum_, scheme, z, size, at, column0, row0, width, height);
    };
    LatticeBlock out = read(*members_.front());
    for (std::size_t m = 1; m < members_.size(); ++m) {
        if (std::all_of(out.valid.begin(), out.valid.end(), [](std::uint8_t v) { return v; })) {
            break;
        }
        const LatticeBlock below = read(*members_[m]);
        for (std::size_t k = 0; k < out.valid.size(); ++k) {
            if (!out.valid[k] && below.valid[k]) {
                out.heights[k] = below.heights[k];
                out.valid[k] = 1;
            }
        }
    }
    return out;
}

std::vector<CheckCell> MemberSummaries::cells(const TileRaster& raster, int z) const {
    std::vector<CheckCell> out;
    for (std::size_t m = 0; m < members_.size(); ++m) {
        const Member& member = *members_[m];
        if (!reads_summary(m, z) || !meets(member.source->footprint(), raster.bounds)) {
            continue;
        }
        const DemSummary& sum = summary(member);
        const int at = summary_level(sum, *member.place, options_.scheme, z, options_.tile_size);
        const std::vector<CheckCell> some = summary_cells(sum, *member.place, raster, at);
        out.insert(out.end(), some.begin(), some.end());
    }
    return out;
}

void MemberSummaries::pixels_in(const LonLatBox& box,
                                int z,
                                const DemSource::PixelVisitor& visit) const {
    for (std::size_t m = 0; m < members_.size(); ++m) {
        if (!reads_summary(m, z) && meets(members_[m]->source->footprint(), box)) {
            members_[m]->source->pixels_in(box, visit);
        }
    }
}

std::size_t MemberSummaries::window_pixels(const LonLatBox& box, int z) const {
    std::size_t sum = 0;
    for (std::size_t m = 0; m < members_.size(); ++m) {
        if (!reads_summary(m, z) && meets(members_[m]->source->footprint(), box)) {
            sum += members_[m]->source->window_pixels(box);
        }
    }
    return sum;
}

} // namespace tb::tiler
