// The multi-resolution summary (see dem_summary.hpp): planes and exact residual ranges per
// block, fitted to the pixels at the finest level and to the children's planes above it.
#include "tiler/summary/dem_summary.hpp"

#include "core/error.hpp"
#include "tiler/log.hpp"
#include "tiler/sources/geoid.hpp"

#include <algorithm>
#include <limits>

namespace tb::tiler {
namespace {

// Least-squares plane h = a + b u + c v through weighted points, from their moments.
struct Moments {
    double n = 0, su = 0, sv = 0, sh = 0, suu = 0, suv = 0, svv = 0, suh = 0, svh = 0;
    void add(double u, double v, double h) {
        n += 1, su += u, sv += v, sh += h;
        suu += u * u, suv += u * v, svv += v * v, suh += u * h, svh += v * h;
    }
    // The plane through the points' centroid; flat (b = c = 0) where they do not span a plane
    // (one point, or all on a line), which any plane may stand for: the range makes it true.
    void solve(double& a, double& b, double& c) const {
        const double mu = su / n, mv = sv / n, mh = sh / n;
        const double cuu = suu / n - mu * mu, cuv = suv / n - mu * mv, cvv = svv / n - mv * mv;
        const double cuh = suh / n - mu * mh, cvh = svh / n - mv * mh;
        const double det = cuu * cvv - cuv * cuv;
        b = c = 0;
        if (det > 1e-9 * std::max(1.0, cuu * cvv)) {
            b = (cuh * cvv - cvh * cuv) / det;
            c = (cvh * cuu - cuh * cuv) / det;
        }
        a = mh - b * mu - c * mv;
    }
};

// The range [lo, hi] widened to floats that hold it, with a hair for the double arithmetic
// that evaluates a plane in different orders.
void set_range(SummaryBlock& block, double lo, double hi) {
    const double pad = 1e-6 + 1e-12 * std::max(std::abs(lo), std::abs(hi));
    lo -= pad, hi += pad;
    float l = static_cast<float>(lo), h = static_cast<float>(hi);
    if (static_cast<double>(l) > lo) {
        l = std::nextafter(l, -std::numeric_limits<float>::infinity());
    }
    if (static_cast<double>(h) < hi) {
        h = std::nextafter(h, std::numeric_limits<float>::infinity());
    }
    block.low = l, block.high = h;
}

constexpr SummaryBlock kEmpty{0, 0, 0, 1, 0};

} // namespace

std::int64_t DemSummary::blocks_across(int level) const {
    const std::int64_t side = std::int64_t{1} << level;
    return (width_ + side - 1) / side;
}

std::int64_t DemSummary::blocks_down(int level) const {
    const std::int64_t side = std::int64_t{1} << level;
    return (height_ + side - 1) / side;
}

std::int64_t DemSummary::last_column(int level, std::int64_t bx) const {
    return std::min<std::int64_t>(((bx + 1) << level) - 1, width_ - 1);
}

std::int64_t DemSummary::last_row(int level, std::int64_t by) const {
    return std::min<std::int64_t>(((by + 1) << level) - 1, height_ - 1);
}

const SummaryBlock* DemSummary::block(int level, std::int64_t bx, std::int64_t by) const {
    TB_ASSERT(level >= finest_level() && level <= coarsest_level());
    if (bx < 0 || by < 0 || bx >= blocks_across(level) || by >= blocks_down(level)) {
        return nullptr;
    }
    return &levels_[static_cast<std::size_t>(level - finest_)]
                   [static_cast<std::size_t>(by * blocks_across(level) + bx)];
}

std::size_t DemSummary::bytes() const {
    std::size_t total = 0;
    for (const auto& level : levels_) {
        total += level.size() * sizeof(SummaryBlock);
    }
    return total;
}

namespace {

// One block of level k (the finest) from its pixels (heights ellipsoidal, NaN for voids), `px`
// the window read, (column0, row0) its first pixel, `w` its width.
SummaryBlock fit_pixels(const std::vector<double>& px,
                        int k,
                        int w,
                        std::int64_t column0,
                        std::int64_t row0,
                        std::int64_t bx,
                        std::int64_t by,
                        std::int64_t last_col,
                        std::int64_t last_row) {
    const double ci = DemSummary::centre(k, bx), cj = DemSummary::centre(k, by);
    const auto at = [&](std::int64_t i, std::int64_t j) {
        return px[static_cast<std::size_t>((j - row0) * w + (i - column0))];
    };
    Moments m;
    for (std::int64_t j = by << k; j <= last_row; ++j) {
        for (std::int64_t i = bx << k; i <= last_col; ++i) {
            const double h = at(i, j);
            if (!std::isnan(h)) {
                m.add(static_cast<double>(i) - ci, static_cast<double>(j) - cj, h);
            }
        }
    }
    if (m.n == 0) {
        return kEmpty;
    }
    double a = 0, b = 0, c = 0;
    m.solve(a, b, c);
    SummaryBlock block{static_cast<float>(a), static_cast<float>(b), static_cast<float>(c), 0, 0};
    double lo = INFINITY, hi = -INFINITY;
    for (std::int64_t j = by << k; j <= last_row; ++j) {
        for (std::int64_t i = bx << k; i <= last_col; ++i) {
            const double h = at(i, j);
            if (!std::isnan(h)) {
                const double r = h - DemSummary::plane(block, k, bx, by, double(i), double(j));
                lo = std::min(lo, r), hi = std::max(hi, r);
            }
        }
    }
    set_range(block, lo, hi);
    return block;
}

} // namespace

// One block of level `level` from its children at level - 1 (see the header).
SummaryBlock DemSummary::fit_children(int level, std::int64_t bx, std::int64_t by) const {
    const int child = level - 1;
    struct Corner {
        double i, j, h;
    };
    std::vector<Corner> corners;
    corners.reserve(16);
    std::array<std::pair<std::int64_t, std::int64_t>, 4> kids{};
    int count = 0;
    for (int q = 0; q < 4; ++q) {
        const std::int64_t cx = 2 * bx + (q & 1), cy = 2 * by + (q >> 1);
        const SummaryBlock* c = block(child, cx, cy);
        if (c == nullptr || c->empty()) {
            continue;
        }
        kids[static_cast<std::size_t>(count++)] = {cx, cy};
        for (int r = 0; r < 4; ++r) {
            const double i = static_cast<double>((r & 1) ? last_column(child, cx) : cx << child);
            const double j = static_cast<double>((r >> 1) ? last_row(child, cy) : cy << child);
            corners.push_back({i, j, plane(*c, child, cx, cy, i, j)});
        }
    }
    if (count == 0) {
        return kEmpty;
    }
    const double ci = centre(level, bx), cj = centre(level, by);
    Moments m;
    for (const Corner& c : corners) {
        m.add(c.i - ci, c.j - cj, c.h);
    }
    double a = 0, b = 0, c = 0;
    m.solve(a, b, c);
    SummaryBlock out{static_cast<float>(a), static_cast<float>(b), static_cast<float>(c), 0, 0};
    double lo = INFINITY, hi = -INFINITY;
    for (int q = 0; q < count; ++q) {
        const SummaryBlock& kid = *block(child,
                                         kids[static_cast<std::size_t>(q)].first,
                                         kids[static_cast<std::size_t>(q)].second);
        for (int r = 0; r < 4; ++r) {
            const Corner& p = corners[static_cast<std::size_t>(4 * q + r)];
            const double d = p.h - plane(out, level, bx, by, p.i, p.j);
            lo = std::min(lo, d + static_cast<double>(kid.low));
            hi = std::max(hi, d + static_cast<double>(kid.high));
        }
    }
    set_range(out, lo, hi);
    return out;
}

int summary_finest_level(std::int64_t width, std::int64_t height) {
    int level = kFinestLevel;
    const auto blocks = [&](int k) {
        const std::int64_t side = std::int64_t{1} << k;
        return ((width + side - 1) / side) * ((height + side - 1) / side);
    };
    while (blocks(level) > kMaxFinestBlocks) {
        ++level;
    }
    return level;
}

namespace {

// Adds the EGM96 undulation at each pixel centre of a window: by row and column on an
// axis-aligned grid (`columns` made for it: a column's longitude and a row's latitude are each
// its own), else at each centre moved to lon/lat.
void add_undulation(std::vector<double>& px,
                    const std::string& path,
                    const PixelPlace& place,
                    const std::vector<Egm96Column>& columns,
                    std::int64_t column0,
                    std::int64_t row0,
                    int width,
                    int height) {
    std::vector<double> lon, lat;
    for (int j = 0; j < height; ++j) {
        double* row = px.data() + static_cast<std::size_t>(j) * width;
        if (place.grid()) {
            lon.assign(1, static_cast<double>(column0));
            lat.assign(1, static_cast<double>(row0 + j));
            place.to_lonlat(lon, lat);
            const Egm96Row r = egm96_row(lat[0]);
            for (int i = 0; i < width; ++i) {
                row[i] += egm96_at(columns[static_cast<std::size_t>(column0 + i)], r);
            }
            continue;
        }
        place.row_to_lonlat(static_cast<double>(column0),
                            1.0,
                            static_cast<double>(row0 + j),
                            width,
                            place.fine_span(),
                            lon,
                            lat);
        for (int i = 0; i < width; ++i) {
            const auto k = static_cast<std::size_t>(i);
            if (!std::isnan(row[i])) {
                if (std::isnan(lon[k])) {
                    throw InputError(path + ": pixel (" + std::to_string(column0 + i) + ", " +
                                     std::to_string(row0 + j) +
                                     ") does not transform to lon/lat; check the DEM's CRS");
                }
                row[i] += egm96_undulation(lon[k], lat[k]);
            }
        }
    }
}

} // namespace

void DemSummary::fit_window(const DemSource& source,
                            const PixelPlace& place,
                            const std::vector<Egm96Column>& columns,
                            VerticalDatum datum,
                            std::int64_t column0,
                            std::int64_t row0,
                            int width,
                            int height) {
    const int k = finest_;
    if (source.window_empty(column0, row0, width, height)) {
        return; // its blocks stay empty
    }
    std::vector<double> px = source.read_pixels(column0, row0, width, height);
    if (datum == VerticalDatum::Egm96) {
        add_undulation(px, source.info().path, place, columns, column0, row0, width, height);
    }
    auto& finest = levels_.front();
    const std::int64_t across = blocks_across(k);
    for (std::int64_t by = row0 >> k; by <= (row0 + height - 1) >> k; ++by) {
        for (std::int64_t bx = column0 >> k; bx <= (column0 + width - 1) >> k; ++bx) {
            finest[static_cast<std::size_t>(by * across + bx)] = fit_pixels(
                px, k, width, column0, row0, bx, by, last_column(k, bx), last_row(k, by));
        }
    }
}

DemSummary
DemSummary::build(const DemSource& source, const PixelPlace& place, VerticalDatum datum) {
    DemSummary s;
    s.width_ = place.width();
    s.height_ = place.height();
    s.finest_ = summary_finest_level(s.width_, s.height_);
    const std::string& path = source.info().path;
    log::info(path + ": making its multi-resolution summary (" + std::to_string(s.width_) + " x " +
              std::to_string(s.height_) + " pixels, blocks of " + std::to_string(1 << s.finest_) +
              " pixels and up)");
    std::vector<Egm96Column> columns;
    if (datum == VerticalDatum::Egm96 && place.grid()) {
        std::vector<double> lon(static_cast<std::size_t>(s.width_)), lat(lon.size(), 0.0);
        for (std::size_t i = 0; i < lon.size(); ++i) {
            lon[i] = static_cast<double>(i);
        }
        place.to_lonlat(lon, lat);
        columns.resize(lon.size());
        for (std::size_t i = 0; i < lon.size(); ++i) {
            columns[i] = egm96_column(lon[i]);
        }
    }
    const int W = s.width_, H = s.height_;
    // Windows of at most 256 x 2048 pixels (16 MiB of doubles), whole blocks each.
    const int rows = std::max(256, 1 << s.finest_), cols = std::max(2048, 1 << s.finest_);
    s.levels_.emplace_back(
        static_cast<std::size_t>(s.blocks_across(s.finest_) * s.blocks_down(s.finest_)), kEmpty);
    int reported = 0;
    for (std::int64_t row0 = 0; row0 < H; row0 += rows) {
        const int h = static_cast<int>(std::min<std::int64_t>(rows, H - row0));
        for (std::int64_t column0 = 0; column0 < W; column0 += cols) {
            const int w = static_cast<int>(std::min<std::int64_t>(cols, W - column0));
            s.fit_window(source, place, columns, datum, column0, row0, w, h);
        }
        const int percent = static_cast<int>(100 * (row0 + h) / H);
        if (percent >= reported + 10 || row0 + h == H) {
            reported = percent;
            log::info(path + ": summary " + std::to_string(percent) + " % read");
        }
    }
    for (int level = s.finest_ + 1; s.blocks_across(level - 1) > 1 || s.blocks_down(level - 1) > 1;
         ++level) {
        std::vector<SummaryBlock> blocks;
        blocks.reserve(static_cast<std::size_t>(s.blocks_across(level) * s.blocks_down(level)));
        for (std::int64_t by = 0; by < s.blocks_down(level); ++by) {
            for (std::int64_t bx = 0; bx < s.blocks_across(level); ++bx) {
                blocks.push_back(s.fit_children(level, bx, by));
            }
        }
        s.levels_.push_back(std::move(blocks));
    }
    log::info(path + ": summary ready, levels " + std::to_string(s.finest_level()) + ".." +
              std::to_string(s.coarsest_level()) + ", " + std::to_string(s.bytes() / 1024) +
              " KiB");
    return s;
}

std::optional<DemSummary>
DemSummary::from_levels(int width, int height, std::vector<std::vector<SummaryBlock>> levels) {
    if (width < 1 || height < 1 || levels.empty()) {
        return std::nullopt;
    }
    DemSummary s;
    s.width_ = width;
    s.height_ = height;
    s.finest_ = summary_finest_level(width, height);
    for (std::size_t k = 0; k < levels.size(); ++k) {
        const int level = s.finest_ + static_cast<int>(k);
        const bool last = s.blocks_across(level) == 1 && s.blocks_down(level) == 1;
        const auto count = static_cast<std::size_t>(s.blocks_across(level) * s.blocks_down(level));
        // The coarsest level is the first of one block (or the finest when that is one block).
        if (levels[k].size() != count || last != (k + 1 == levels.size())) {
            return std::nullopt;
        }
    }
    s.levels_ = std::move(levels);
    return s;
}

} // namespace tb::tiler
