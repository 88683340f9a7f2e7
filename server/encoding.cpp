// Accept-Encoding negotiation and compression.
#include "server/encoding.hpp"
#include "server/request_head.hpp"
#include "tiler/gzip.hpp"

#include <brotli/encode.h>

#include <algorithm>
#include <cstring>
#include <stdexcept>

namespace tb::server {
namespace {

// A qvalue (RFC 9110 section 12.4.2) in thousandths: "0", "0.5", "1", "1.000"; -1 if malformed.
int parse_qvalue(std::string_view q) {
    if (q.empty() || q.size() > 5 || (q[0] != '0' && q[0] != '1')) {
        return -1;
    }
    int value = (q[0] - '0') * 1000;
    if (q.size() == 1) {
        return value;
    }
    if (q[1] != '.') {
        return -1;
    }
    int scale = 100;
    for (std::size_t i = 2; i < q.size(); ++i, scale /= 10) {
        if (q[i] < '0' || q[i] > '9') {
            return -1;
        }
        value += (q[i] - '0') * scale;
    }
    return value > 1000 ? -1 : value;
}

} // namespace

Coding pick_coding(std::string_view accept) {
    int gzip = -1, br = -1, any = -1; // q in thousandths; -1: not named
    while (!accept.empty()) {
        const std::size_t comma = accept.find(',');
        std::string_view item = accept.substr(0, comma);
        accept = comma == std::string_view::npos ? std::string_view() : accept.substr(comma + 1);
        const std::size_t semi = item.find(';');
        const std::string_view coding = trim_ows(item.substr(0, semi));
        int q = 1000;
        if (semi != std::string_view::npos) {
            std::string_view params = item.substr(semi + 1);
            q = -1;
            // Only the q parameter is defined for Accept-Encoding.
            const std::string_view p = trim_ows(params);
            if (p.size() >= 2 && (p[0] == 'q' || p[0] == 'Q') && p[1] == '=') {
                q = parse_qvalue(trim_ows(p.substr(2)));
            }
            if (q < 0) {
                continue; // malformed: ignore the item
            }
        }
        if (equals_ci(coding, "gzip") || equals_ci(coding, "x-gzip")) {
            gzip = std::max(gzip, q);
        } else if (equals_ci(coding, "br")) {
            br = std::max(br, q);
        } else if (coding == "*") {
            any = std::max(any, q);
        }
    }
    if (gzip < 0) {
        gzip = any;
    }
    if (br < 0) {
        br = any;
    }
    if (br > 0 && br >= gzip) {
        return Coding::Brotli;
    }
    if (gzip > 0) {
        return Coding::Gzip;
    }
    return Coding::Identity;
}

const char* coding_name(Coding coding) {
    switch (coding) {
    case Coding::Gzip:
        return "gzip";
    case Coding::Brotli:
        return "br";
    default:
        return nullptr;
    }
}

std::string compress(std::string_view bytes, Coding coding) {
    if (coding == Coding::Brotli) {
        std::string out(BrotliEncoderMaxCompressedSize(bytes.size()), '\0');
        std::size_t size = out.size();
        if (out.empty() || !BrotliEncoderCompress(BROTLI_DEFAULT_QUALITY,
                                                  BROTLI_DEFAULT_WINDOW,
                                                  BROTLI_MODE_TEXT,
                                                  bytes.size(),
                                                  reinterpret_cast<const uint8_t*>(bytes.data()),
                                                  &size,
                                                  reinterpret_cast<uint8_t*>(out.data()))) {
            throw std::runtime_error("brotli compression failed");
        }
        out.resize(size);
        return out;
    }
    if (coding == Coding::Gzip) {
        return tiler::gzip_compress(bytes, 6);
    }
    return std::string(bytes);
}

} // namespace tb::server
