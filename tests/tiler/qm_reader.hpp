#pragma once
// A quantized-mesh-1.0 reader written from the format's README, sharing no code with tiler/:
// the header, the zig-zag delta vertex arrays, high-water-mark indices (16 or 32 bits, with the
// 4-byte alignment padding), the four edge lists and the extensions, every length checked
// against the bytes. The tests judge the encoder with it.
#include <doctest/doctest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

namespace tb_qm {

struct Extension {
    int id = 0;
    std::string data;
};

struct Tile {
    std::array<double, 3> centre{};
    float min_height = 0, max_height = 0;
    std::array<double, 4> sphere{}; // centre x, y, z, radius
    std::array<double, 3> horizon{};
    std::uint32_t vertex_count = 0;
    std::vector<std::uint16_t> u, v, h;
    bool wide = false;           // 32-bit indices
    std::size_t index_start = 0; // byte offset of the triangle count
    std::vector<std::uint32_t> triangles;
    std::array<std::vector<std::uint32_t>, 4> edges; // west, south, east, north
    std::vector<Extension> extensions;

    const Extension* extension(int id) const {
        for (const auto& e : extensions) {
            if (e.id == id) {
                return &e;
            }
        }
        return nullptr;
    }
    double lon(std::size_t i, double west, double east) const {
        return west + (east - west) * u[i] / 32767.0;
    }
    double lat(std::size_t i, double south, double north) const {
        return south + (north - south) * v[i] / 32767.0;
    }
    double height(std::size_t i) const {
        return min_height + (static_cast<double>(max_height) - min_height) * h[i] / 32767.0;
    }
};

class Bytes {
public:
    explicit Bytes(const std::string& b) : b_(b) {}
    template <class T> T get() {
        REQUIRE_MESSAGE(pos_ + sizeof(T) <= b_.size(), "read past the end at byte " << pos_);
        T v;
        std::memcpy(&v, b_.data() + pos_, sizeof v); // the test machine is little-endian
        pos_ += sizeof v;
        return v;
    }
    std::size_t pos() const { return pos_; }
    void skip(std::size_t n) {
        REQUIRE(pos_ + n <= b_.size());
        pos_ += n;
    }
    bool done() const { return pos_ == b_.size(); }
    std::string take(std::size_t n) {
        REQUIRE_MESSAGE(pos_ + n <= b_.size(), "extension runs past the end");
        std::string s = b_.substr(pos_, n);
        pos_ += n;
        return s;
    }

private:
    const std::string& b_;
    std::size_t pos_ = 0;
};

inline Tile read(const std::string& bytes) {
    Tile t;
    Bytes in(bytes);
    for (double& c : t.centre) {
        c = in.get<double>();
    }
    t.min_height = in.get<float>();
    t.max_height = in.get<float>();
    for (double& c : t.sphere) {
        c = in.get<double>();
    }
    for (double& c : t.horizon) {
        c = in.get<double>();
    }
    REQUIRE(in.pos() == 88);
    t.vertex_count = in.get<std::uint32_t>();
    for (auto* a : {&t.u, &t.v, &t.h}) {
        int value = 0;
        for (std::uint32_t i = 0; i < t.vertex_count; ++i) {
            const std::uint16_t z = in.get<std::uint16_t>();
            value += (z >> 1) ^ (-(z & 1));
            REQUIRE(value >= 0);
            REQUIRE(value <= 32767);
            a->push_back(static_cast<std::uint16_t>(value));
        }
    }
    t.wide = t.vertex_count > 65536;
    if (t.wide && in.pos() % 4 != 0) {
        const std::size_t pad = 4 - in.pos() % 4;
        for (std::size_t k = 0; k < pad; ++k) {
            CHECK(in.get<std::uint8_t>() == 0);
        }
    }
    t.index_start = in.pos();
    const auto index = [&]() -> std::uint32_t {
        return t.wide ? in.get<std::uint32_t>() : in.get<std::uint16_t>();
    };
    const std::uint32_t triangle_count = in.get<std::uint32_t>();
    std::uint32_t highest = 0;
    for (std::uint32_t k = 0; k < 3 * triangle_count; ++k) {
        const std::uint32_t code = index();
        REQUIRE_MESSAGE(code <= highest, "high-water-mark code " << code << " above " << highest);
        t.triangles.push_back(highest - code);
        if (code == 0) {
            ++highest;
        }
    }
    for (auto& edge : t.edges) {
        const std::uint32_t count = in.get<std::uint32_t>();
        for (std::uint32_t k = 0; k < count; ++k) {
            edge.push_back(index());
            REQUIRE(edge.back() < t.vertex_count);
        }
    }
    while (!in.done()) {
        Extension e;
        e.id = in.get<std::uint8_t>();
        const std::uint32_t length = in.get<std::uint32_t>();
        e.data = in.take(length);
        t.extensions.push_back(std::move(e));
    }
    return t;
}

// CesiumJS's oct decoding of 8-bit components (AttributeCompression.octDecode), as the format's
// README gives it.
inline std::array<double, 3> oct_decode(std::uint8_t a, std::uint8_t b) {
    double x = a / 255.0 * 2 - 1, y = b / 255.0 * 2 - 1;
    const double z = 1 - std::abs(x) - std::abs(y);
    if (z < 0) {
        const double ox = x;
        x = (1 - std::abs(y)) * (ox < 0 ? -1 : 1);
        y = (1 - std::abs(ox)) * (y < 0 ? -1 : 1);
    }
    const double len = std::sqrt(x * x + y * y + z * z);
    return {x / len, y / len, z / len};
}

} // namespace tb_qm
