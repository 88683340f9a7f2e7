#include "tiler/json_number.hpp"

#include "core/error.hpp"

#include <charconv>
#include <cmath>

namespace tb::tiler {

std::string json_number(double v, std::string_view what) {
    if (!std::isfinite(v)) {
        throw InputError("cannot write " + std::string(what) + " of " +
                         (std::isnan(v) ? "NaN"
                          : v > 0       ? "+infinity"
                                        : "-infinity") +
                         " into JSON, which has no such number; check the input for infinite "
                         "or NaN values that are not marked as nodata");
    }
    char buf[32];
    const auto r = std::to_chars(buf, buf + sizeof buf, v);
    return std::string(buf, r.ptr);
}

} // namespace tb::tiler
