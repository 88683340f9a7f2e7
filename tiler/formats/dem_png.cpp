// PNG writer for raster DEM tiles (PNG specification, W3C 2003: §5 datastream, §9 filtering,
// §10 zlib compression, §11.2.2 IHDR), with the terrarium and mapbox height packings.
#include "tiler/formats/dem_png.hpp"

#include "core/error.hpp"

#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <vector>

namespace tb::tiler {
namespace {

constexpr std::uint32_t kMaxCode = (1u << 24) - 1;

void put_u32(std::string& out, std::uint32_t v) {
    out += static_cast<char>(v >> 24);
    out += static_cast<char>((v >> 16) & 0xff);
    out += static_cast<char>((v >> 8) & 0xff);
    out += static_cast<char>(v & 0xff);
}

// A chunk: length, type, data, CRC-32 of type and data.
void put_chunk(std::string& out, const char type[4], const std::string& data) {
    put_u32(out, static_cast<std::uint32_t>(data.size()));
    const std::size_t start = out.size();
    out.append(type, 4);
    out += data;
    uLong crc = crc32(0L, Z_NULL, 0);
    crc = crc32(crc,
                reinterpret_cast<const Bytef*>(out.data() + start),
                static_cast<uInt>(out.size() - start));
    put_u32(out, static_cast<std::uint32_t>(crc));
}

// The Paeth predictor (§9.4).
int paeth(int a, int b, int c) {
    const int p = a + b - c;
    const int pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
    if (pa <= pb && pa <= pc) {
        return a;
    }
    return pb <= pc ? b : c;
}

} // namespace

std::uint32_t encode_height(double h, Format format) {
    TB_ASSERT(is_dem_format(format) && std::isfinite(h));
    const double code = format == Format::Terrarium ? std::round((h + 32768.0) * 256.0)
                                                    : std::round((h + 10000.0) * 10.0);
    return static_cast<std::uint32_t>(std::clamp(code, 0.0, static_cast<double>(kMaxCode)));
}

double decode_height(std::uint32_t code, Format format) {
    TB_ASSERT(is_dem_format(format) && code <= kMaxCode);
    if (format == Format::Terrarium) {
        return static_cast<double>(code >> 16) * 256.0 + static_cast<double>((code >> 8) & 0xff) +
               static_cast<double>(code & 0xff) / 256.0 - 32768.0;
    }
    return -10000.0 + static_cast<double>(code) * 0.1;
}

double height_step(Format format) {
    TB_ASSERT(is_dem_format(format));
    return format == Format::Terrarium ? 1.0 / 256.0 : 0.1;
}

std::string encode_dem_png(std::span<const double> heights, int width, int height, Format format) {
    TB_ASSERT(width >= 1 && height >= 1 && width <= 65535 && height <= 65535);
    TB_ASSERT(heights.size() == static_cast<std::size_t>(width) * height);
    constexpr int kBpp = 3; // bytes per pixel: R, G, B
    const std::size_t stride = static_cast<std::size_t>(width) * kBpp;

    // Scanlines, each prefixed by its filter type byte.
    std::vector<unsigned char> raw(stride * height);
    for (std::size_t k = 0; k < heights.size(); ++k) {
        const std::uint32_t code = encode_height(heights[k], format);
        raw[k * 3] = static_cast<unsigned char>(code >> 16);
        raw[k * 3 + 1] = static_cast<unsigned char>((code >> 8) & 0xff);
        raw[k * 3 + 2] = static_cast<unsigned char>(code & 0xff);
    }
    std::vector<unsigned char> filtered((stride + 1) * height);
    std::vector<unsigned char> candidate[5];
    for (auto& c : candidate) {
        c.resize(stride);
    }
    const std::vector<unsigned char> zeros(stride, 0);
    for (int j = 0; j < height; ++j) {
        const unsigned char* line = raw.data() + stride * j;
        const unsigned char* up = j > 0 ? raw.data() + stride * (j - 1) : zeros.data();
        for (std::size_t i = 0; i < stride; ++i) {
            const int a = i >= kBpp ? line[i - kBpp] : 0;
            const int b = up[i];
            const int c = i >= kBpp ? up[i - kBpp] : 0;
            const int x = line[i];
            candidate[0][i] = static_cast<unsigned char>(x);
            candidate[1][i] = static_cast<unsigned char>(x - a);
            candidate[2][i] = static_cast<unsigned char>(x - b);
            candidate[3][i] = static_cast<unsigned char>(x - (a + b) / 2);
            candidate[4][i] = static_cast<unsigned char>(x - paeth(a, b, c));
        }
        // Bytes read as signed; the smallest sum of magnitudes usually deflates best.
        int best = 0;
        long best_cost = -1;
        for (int f = 0; f < 5; ++f) {
            long cost = 0;
            for (unsigned char v : candidate[f]) {
                cost += v < 128 ? v : 256 - v;
            }
            if (best_cost < 0 || cost < best_cost) {
                best = f, best_cost = cost;
            }
        }
        unsigned char* out = filtered.data() + (stride + 1) * j;
        out[0] = static_cast<unsigned char>(best);
        std::copy(candidate[best].begin(), candidate[best].end(), out + 1);
    }

    uLongf packed_size = compressBound(static_cast<uLong>(filtered.size()));
    std::string packed(packed_size, '\0');
    if (compress2(reinterpret_cast<Bytef*>(packed.data()),
                  &packed_size,
                  filtered.data(),
                  static_cast<uLong>(filtered.size()),
                  6) != Z_OK) {
        throw Error("PNG encoding: zlib failed to compress a " + std::to_string(width) + " x " +
                    std::to_string(height) + " tile");
    }
    packed.resize(packed_size);

    std::string png("\x89PNG\r\n\x1a\n", 8);
    std::string header;
    put_u32(header, static_cast<std::uint32_t>(width));
    put_u32(header, static_cast<std::uint32_t>(height));
    header += '\x08'; // bit depth
    header += '\x02'; // colour type: truecolour
    header += '\x00'; // compression: deflate
    header += '\x00'; // filter method: adaptive
    header += '\x00'; // no interlace
    put_chunk(png, "IHDR", header);
    put_chunk(png, "IDAT", packed);
    put_chunk(png, "IEND", std::string());
    return png;
}

} // namespace tb::tiler
