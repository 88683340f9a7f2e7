#include "tiler/json_number.hpp"

#include "core/error.hpp"

#include <charconv>
#include <cmath>
#include <cstdio>

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

std::string json_string(std::string_view s) {
    std::string out = "\"";
    for (unsigned char c : s) {
        if (c == '"' || c == '\\') {
            out += '\\';
            out += static_cast<char>(c);
        } else if (c < 0x20) {
            char buf[8];
            std::snprintf(buf, sizeof buf, "\\u%04x", c);
            out += buf;
        } else {
            out += static_cast<char>(c);
        }
    }
    return out + "\"";
}

} // namespace tb::tiler
