// Loading or making a layer's summary (layer_summary.hpp).
#include "tiler/summary/layer_summary.hpp"

#include "tiler/summary/summary_file.hpp"

#include <cstdint>
#include <optional>
#include <utility>

namespace tb::tiler {

DemSummary load_or_make_summary(const LayerOptions& options,
                                const std::vector<std::string>& files,
                                const DemSource& source,
                                const PixelPlace& place,
                                VerticalDatum datum) {
    const auto dir =
        summary_dir_for(options.summary_dir, std::int64_t{place.width()} * place.height());
    const auto key =
        dir ? summary_key(files, options.nodata, datum, place, options.valid_range) : std::nullopt;
    if (!key) {
        return DemSummary::build(source, place, datum);
    }
    const auto path = summary_path(*dir, files.front(), *key);
    if (auto kept = load_summary(path, *key)) {
        return std::move(*kept);
    }
    DemSummary made = DemSummary::build(source, place, datum);
    save_summary(path, *key, made);
    return made;
}

} // namespace tb::tiler
